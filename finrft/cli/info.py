"""The commands that describe rather than run: scene, medium, law."""

from __future__ import annotations

import argparse
from typing import Any

from .. import laws, schema
from .. import scene as scenes
from ..experiments.swim import RobotScene
from ..errors import SceneError, UsageError
from ..experiments.flags import add_force, add_json, add_quiet
from ..files import atomic_path
from .common import check_output, print_json, said_written, say


def add_scene(sub: Any) -> None:
    p = sub.add_parser("scene", help="print a resolved scene as TOML",
                       description="Print the full resolved scene (SI units; each key's unit in brackets) as TOML, "
                       "to copy and edit. A --scene file is read as the kind of scene its sections make (plate, "
                       "two-fin robot, your own model, wheel, intrusion).")
    p.add_argument("--dump", metavar="NAME", help=f"preset to print (default: physical): a plate preset "
                   f"({', '.join(scenes.presets(scenes.Scene))}), with --robot a robot preset "
                   f"({', '.join(scenes.presets(RobotScene))}), or '{TEMPLATE}': a template of your own model's "
                   f"scene (finrft run), one of each section")
    p.add_argument("--robot", action="store_true", help="the two-fin robot's scene instead of a plate scene")
    p.add_argument("--scene", metavar="FILE.toml", help="resolve this file (instead of --dump)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key (SI)")
    add_quiet(p)
    p.set_defaults(handler=scene)


# --dump's name of the template of a user's model scene (`finrft run`).
TEMPLATE = "robot"


def template() -> scenes.UserScene:
    """A user's model scene to start from: every section, one [[drive]] and one [[control]] entry, with names to
    replace (MODEL.xml, BODY, JOINT, ACTUATOR)."""
    return scenes.UserScene(model=scenes.Model(path="MODEL.xml", bodies=("BODY",)),
                            drive=(scenes.JointDrive(joint="JOINT"),),
                            control=(scenes.Control(actuator="ACTUATOR"),),
                            sim=scenes.RobotSim(duration=1.0))


def scene(args: argparse.Namespace) -> int:
    if args.scene and args.dump:
        raise UsageError(f"give --scene {args.scene} or --dump {args.dump}, not both")
    if args.dump == TEMPLATE and args.robot:
        raise UsageError(f"--dump {TEMPLATE} is the template of your own model's scene (finrft run): leave out "
                         f"--robot, or dump a preset of the two-fin robot (--robot --dump paper or physical)")
    if args.dump == TEMPLATE:
        overrides = dict(scenes.parse_override(item, scenes.UserScene) for item in args.set)
        print(f"# Your own model in the medium (finrft run --scene FILE.toml): replace MODEL.xml, BODY, JOINT and "
              f"ACTUATOR\n# by your model's names; leave out [[drive]] or [[control]] entries you do not need.\n"
              + scenes.to_toml(template().replace(**overrides)), end="")
        return 0
    kind = RobotScene if args.robot else _kind_of(args.scene)
    overrides = dict(scenes.parse_override(item, kind) for item in args.set)
    resolved = scenes.load_scene(args.scene, preset_name=args.dump or "physical", overrides=overrides, cls=kind)
    print(scenes.to_toml(resolved), end="")
    return 0


def _kind_of(path: str | None) -> type:
    """The registered scene kind whose sections hold every section of the file at ``path`` (a plate scene when
    several do, or no file is given); the file's own errors are left to reading it."""
    from ..files import read_text, read_toml
    if path is None:
        return scenes.Scene
    try:
        given = set(read_toml(read_text(path, "scene file"), path))
    except SceneError:
        return scenes.Scene
    fits = [kind.cls for kind in scenes.scene_kinds() if given <= set(schema.sections(kind.cls))]
    return scenes.Scene if not fits or scenes.Scene in fits else fits[0]


def add_medium(sub: Any) -> None:
    p = sub.add_parser("medium", help="the catalogue of named granular media, with units and sources",
                       description="Print the named media of the catalogue (finrft/media.toml) that scenes "
                       "(medium.name) and `finrft law --medium` take: each value with its unit and source, what is "
                       "unverified, and what could not be found.")
    p.add_argument("name", nargs="?", metavar="NAME", help="one medium (default: --list)")
    p.add_argument("--list", action="store_true", help="every medium (the default)")
    add_json(p, "the media (each value with its unit and source)")
    add_quiet(p)
    p.set_defaults(handler=medium)


def medium(args: argparse.Namespace) -> int:
    from .. import media
    if args.name is not None and args.list:
        raise UsageError(f"give a medium's NAME ({args.name}) or --list, not both")
    chosen = (media.medium(args.name),) if args.name is not None else media.media()
    say(args, "\n\n".join(media.describe(m) for m in chosen))
    print_json(args, [m.to_dict() for m in chosen])
    return 0


def add_law(sub: Any) -> None:
    p = sub.add_parser("law", help="a force law's stress map in a medium (li2013, rft3d: alpha_x, alpha_z over "
                       "beta, gamma; sandswim: F_perp, F_par over psi, gamma0)",
                       description="Evaluate a law's stress per unit depth over its angles, as in the papers' "
                       "figures: for li2013, alpha_x and alpha_z (N/cm^3) over the plate angle beta and the velocity "
                       "angle gamma, both -90..90 deg at 5 deg, for the medium's zeta; for rft3d the same in the "
                       "vertical plane (psi = 0) for the medium's xi_n (from its bulk density and internal friction; "
                       "generic: 1 N/cm^3); for sandswim, F_perp and F_par per unit C_S and C_F over the angle psi "
                       "between velocity and body axis (0..90 deg at 1 deg) and gamma0.")
    p.add_argument("name", metavar="NAME", help=f"the law: {', '.join(laws.mapped())}")
    p.add_argument("--medium", default="generic", metavar="M",
                   help="a medium of the catalogue (finrft medium --list; default: %(default)s)")
    p.add_argument("--plot", metavar="FILE.png", help="write the map as a figure, one colour map per field")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print the map as JSON, alone on stdout (the text goes to "
                   "stderr): law, the two angle axes (_deg) and each field, flat lists of one entry per grid point")
    add_quiet(p)
    p.set_defaults(handler=law)


def law(args: argparse.Namespace) -> int:
    from .. import lawmap
    check_output(args.plot, ".png", "--plot", args.force)
    data = lawmap.stress_map(args.name, args.medium)
    if args.plot:
        with atomic_path(args.plot) as tmp:
            lawmap.plot(args.name, args.medium, data, tmp)
    (xkey, x), (ykey, y), *fields = data.items()
    units = lawmap.law_module(args.name).MAP_UNITS
    say(args, f"{args.name} in {args.medium}: {len(x)} points, {xkey} in [{x.min():g}, {x.max():g}], {ykey} in "
        f"[{y.min():g}, {y.max():g}]")
    for key, values in fields:
        say(args, f"  {key}: {values.min():.4g} to {values.max():.4g} {units[key]}")
    if lawmap.note(args.name, args.medium):
        say(args, f"  {lawmap.note(args.name, args.medium)}")
    said_written(args, (("figure", args.plot),))
    # the fields are in the law's map units (N/cm^3 for li2013), not SI: "units" names them
    print_json(args, {"law": args.name, "units": {key: units[key] for key in list(data)[2:]}, **data})
    return 0


SUBCOMMANDS = (add_scene, add_medium, add_law)
