"""The ``finrft`` command line: a thin layer over the Python API that speaks the paper's units (mm, mm/s, degrees).

Exit status: 0 success, 1 the simulation went unstable or its estimated discretisation error exceeds --max-error,
2 bad input or a file that cannot be read or written (one line on stderr, nothing written), 130 interrupted
(Ctrl-C), 141 stdout closed early (as Unix tools on SIGPIPE). Output paths are checked before anything runs;
every command takes --quiet, every writer --force.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import shlex
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from . import scene as scenes
from .convergence import ErrorLimits, SimulationFailed
from .drive import Drive
from .files import atomic_path
from .experiment import Experiment, Result, run as run_experiment
from .simulate import PlateTest, simulate


class UsageError(Exception):
    """Bad input from the command line; reported in one line with exit status 2."""


class Interrupted(Exception):
    """Ctrl-C: reported in one line (how to continue, when there is a log) with exit status 130."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, not argparse's usage block
        raise UsageError(f"{message} (see '{self.prog} --help')")


def _number(unit: str, *, minimum: float = 0.0, inclusive: bool = False, integer: bool = False) -> Callable:
    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a {'whole ' if integer else ''}number ({unit}), got "
                                             f"'{text}'") from None
        if not math.isfinite(value) or (value < minimum if inclusive else value <= minimum):
            raise argparse.ArgumentTypeError(f"must be {'>=' if inclusive else '>'} {minimum:g}{' ' if unit else ''}"
                                             f"{unit}, got {text}")
        return value
    return parse


PLATE_PRESETS_HELP = ("built-in plate scene when no --scene is given (default: paper): paper = the authors' "
                      "plate with its quirks: inertias of 1 kg m^2, penalty stop, explicit method; physical = "
                      "real inertias, fitted to the measurements, penalty stop, newton method")
ROBOT_PRESETS_HELP = ("built-in robot scene when no --scene is given (default: paper): paper = the authors' model "
                      "with its quirks: inertias of 1 kg m^2, penalty stops, stroke body drag (a constant force "
                      "against the fin's sweep), adaptive method; physical = real inertias, penalty stops, "
                      "velocity body drag (against the body's velocity), adaptive-newton method")


def _add_quiet(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary text (what was asked "
                   "for, files or JSON, is still written)")


def _add_json(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--json", action="store_true", help=f"print {what} as JSON on the last line of stdout (each key "
                   "names its unit: SI, or _deg, _mm where the key says so)")


def _add_force(p: argparse.ArgumentParser) -> None:
    p.add_argument("--force", action="store_true", help="replace output files that exist (default: refuse)")


def _add_plate_scene(p: argparse.ArgumentParser, *, kinds: bool = False, backend: bool = True):
    g = p.add_argument_group("scene")
    if kinds:
        g.add_argument("--plate", choices=("origami", "soft", "rigid"),
                       help="plate kind (overrides plate.kind): origami = one-sided stop, soft = compliant both "
                            "ways, rigid = does not bend")
    g.add_argument("--scene", metavar="FILE.toml", help="plate scene file in SI units (instead of --preset)")
    g.add_argument("--preset", choices=scenes.PRESETS[scenes.Scene], help=PLATE_PRESETS_HELP)
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key in SI units, e.g. --set plate.segment_inertia=0.001 (repeatable)")
    if backend:
        g.add_argument("--backend", choices=("native", "python"),
                       help="where the RFT force is computed (overrides sim.backend; default native, the C "
                            "plugin, falling back to python when it cannot be loaded)")
    return g


def _add_test(p: argparse.ArgumentParser, *, drag: bool) -> None:
    """Flags of the plate tests, drag and rotate."""
    _add_plate_scene(p, kinds=True).add_argument(
        "--cycles", type=_number("cycles", minimum=1, inclusive=True, integer=True), metavar="N",
        help="back-and-forth cycles of the triangle wave (the paper used 5; the first is reported separately); "
             "without it, a single stroke out")
    o = p.add_argument_group("output")
    o.add_argument("--out", metavar="FILE.h5", help="write the time series and the resolved scene to HDF5 (SI units)")
    o.add_argument("--rrd", metavar="FILE.rrd", help="write a rerun recording; open it with 'rerun FILE.rrd'")
    _add_force(o)
    _add_json(o, "a summary")
    _add_quiet(o)
    if drag:
        o.add_argument("--forces-csv", metavar="FILE.csv", help="append the steady force on the plate (normal and "
                       "tangential, N) at this angle of attack to a CSV, for finrft fit-rft (rigid plate only)")
    _add_max_error(p)


def _add_run_outputs(p: argparse.ArgumentParser) -> None:
    """The outputs of a run: HDF5, rerun, --force, --json, --quiet."""
    p.add_argument("--out", metavar="FILE.h5", help="write the time series and the resolved scene (SI units)")
    p.add_argument("--rrd", metavar="FILE.rrd", help="write a rerun recording; open it with 'rerun FILE.rrd'")
    _add_force(p)
    _add_json(p, "a summary")
    _add_quiet(p)


def _add_max_error(p: argparse.ArgumentParser) -> None:
    p.add_argument("--max-error", type=_number("degrees or points"), default=ErrorLimits().angle_deg,
                   metavar="X", help="largest estimated discretisation error accepted, in degrees for angles, "
                   "percentage points for eta and mm for positions (default: %(default)s); every run estimates its own from a companion "
                   "run at another step, and a larger one stops with exit status 1, nothing written")


def _limits(args: argparse.Namespace) -> ErrorLimits:
    return ErrorLimits.uniform(args.max_error)


def _add_workers(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=_number("processes", minimum=1, inclusive=True, integer=True), metavar="N",
                   help="worker processes (default: all cores)")


def _add_search(p: argparse.ArgumentParser, command: str) -> None:
    p.add_argument("--budget", type=_number("evaluations", minimum=1, inclusive=True, integer=True),
                   metavar="EVALS", help="evaluations in all (default: 300, or the log's with --resume; CMA-ES "
                   "finishes the generation it is in)")
    p.add_argument("--seed", type=_number("", minimum=1, inclusive=True, integer=True), metavar="S",
                   help="random seed, >= 1; the same seed gives the same result (default: 1, or the log's with "
                   "--resume)")
    p.add_argument("--out", metavar="LOG.h5", help="new HDF5 log of every evaluation and of the optimiser's state, "
                   "rewritten after each generation (an existing file only with --force)")
    p.add_argument("--resume", metavar="LOG.h5", help=f"continue the run logged in LOG.h5 (a finrft {command} log) "
                   "exactly as if it had not stopped, and go on logging to it")


def _add_robot(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("robot scene")
    g.add_argument("--preset", choices=scenes.PRESETS[scenes.RobotScene], help=ROBOT_PRESETS_HELP)
    g.add_argument("--scene", metavar="FILE.toml", help="robot scene file in SI units (instead of --preset)")
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key in SI units, e.g. --set fin.stiffness=0.4 (repeatable)")
    g.add_argument("--fin", choices=("origami", "soft", "rigid"), help="fin kind (overrides fin.kind)")
    g.add_argument("--model", choices=("full", "half"), help="full robot, or its right half with half the body's "
                   "mass and drag (overrides robot.model)")
    g.add_argument("--backend", choices=("native", "python"), help="where the RFT force is computed")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="finrft", description="Compliant fins in granular media: resistive force theory (RFT) "
                     "on MuJoCo. Command-line flags use the paper's units (mm, mm/s, degrees); scene and HDF5 "
                     "files use SI units, JSON keys name theirs. Every run estimates its own discretisation error. "
                     "Exit status: 0 done, 1 the simulation went unstable or its estimated error exceeds "
                     "--max-error, 2 bad input or a file that cannot be written, 130 interrupted.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    drag = sub.add_parser("drag", help="drag a plate through the medium along +y (the paper's drag test)",
                          description="Drag the plate's base along +y at constant speed: one stroke out from flat "
                          "(the soft, recovery direction of the origami plate), or --cycles back-and-forth cycles. "
                          "Reports the drive force (N) that holds the motion.")
    drag.add_argument("--speed", type=_number("mm/s"), default=30.0, metavar="MM_S",
                      help="drag speed in mm/s (default: %(default)s)")
    drag.add_argument("--distance", type=_number("mm"), default=200.0, metavar="MM",
                      help="stroke length in mm (default: %(default)s)")
    drag.add_argument("--attack", type=_number("degrees", inclusive=True), default=90.0, metavar="DEG",
                      help="angle of attack between the plate and the motion, degrees in 0..180 "
                           "(default: %(default)s, plate normal to the motion)")
    _add_test(drag, drag=True)

    rotate = sub.add_parser("rotate", help="turn a plate about its base (the paper's rotate test)",
                            description="Turn the rod about z through its base at constant angular speed: one "
                            "stroke counter-clockwise from flat along +x, or --cycles back-and-forth cycles. "
                            "Reports the drive torque (N m).")
    rotate.add_argument("--amplitude", type=_number("degrees"), default=120.0, metavar="DEG",
                        help="stroke angle in degrees (default: %(default)s)")
    rotate.add_argument("--omega", type=_number("deg/s"), default=60.0, metavar="DEG_S",
                        help="angular speed in degrees/s (default: %(default)s)")
    _add_test(rotate, drag=False)

    scene = sub.add_parser("scene", help="print a resolved scene as TOML",
                           description="Print the full resolved scene (SI units) as TOML, to copy and edit.")
    scene.add_argument("--dump", metavar="NAME", help=f"preset to print (default: paper): a plate preset "
                       f"({', '.join(scenes.PRESETS[scenes.Scene])}), or with --robot a robot preset "
                       f"({', '.join(scenes.PRESETS[scenes.RobotScene])})")
    scene.add_argument("--robot", action="store_true", help="a robot scene instead of a plate scene")
    scene.add_argument("--scene", metavar="FILE.toml", help="resolve this file (instead of --dump)")
    scene.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key (SI)")
    _add_quiet(scene)

    swim = sub.add_parser("swim", help="the two-fin robot swimming: flap cycles and the swimming efficiency",
                          description="Simulate the robot's flap cycles from rest, the arm at theta2: recovery "
                          "stroke up to theta1, power stroke back. Reports eta = (D1 - D2) / D1 with D1 the distance "
                          "forward in the power stroke and D2 the distance back in the recovery stroke.")
    swim.add_argument("--theta1", type=_number("degrees", minimum=-math.inf), metavar="DEG",
                      help="arm angle at the end of the recovery stroke, degrees in -90..90 (0 sideways, 90 "
                           "forward; default: the scene's, 60 in the presets)")
    swim.add_argument("--theta2", type=_number("degrees", minimum=-math.inf), metavar="DEG",
                      help="arm angle at the end of the power stroke, degrees (default: the scene's, -90 in the "
                           "presets)")
    swim.add_argument("--arm-length", type=_number("mm"), metavar="MM",
                      help="arm length L_a in mm (default: the scene's, 65 in the presets)")
    swim.add_argument("--omega", type=_number("deg/s"), metavar="DEG_S",
                      help="arm angular speed in degrees/s (default: the scene's, 66 in the presets)")
    swim.add_argument("--cycles", type=_number("cycles", minimum=1, inclusive=True, integer=True),
                      metavar="N", help="flap cycles (default: the scene's gait.cycles: 1 in the paper preset, 2 in "
                      "the physical one); figures are the last cycle's, and eta over cycles 2..N")
    _add_robot(swim)
    _add_max_error(swim)
    _add_run_outputs(swim)

    optimize = sub.add_parser("optimize", help="optimise the gait with CMA-ES",
                              description="Maximise the swimming efficiency eta over one flap cycle with CMA-ES "
                              "(pycma): by default over theta1 in [0, 90] deg, theta2 in [-90, 0] deg and the arm "
                              "length in [60, 85] mm. Every evaluation is logged to HDF5 after each generation.")
    _add_search(optimize, "optimize")
    optimize.add_argument("--bounds", action="append", default=[], metavar="KEY=LOW:HIGH",
                          help="search a scene key between bounds, in mm for a length, deg for an angle, else SI "
                               "(the schema's unit), e.g. gait.theta1=10:80, fin.segment_length=10:40, "
                               "fin.stiffness=0.1:2 (repeatable; replaces the default bounds of that key)")
    _add_workers(optimize)
    optimize.add_argument("--executor", choices=("local", "dask"), default="local",
                          help="where evaluations run: local processes, or a Dask cluster (needs finrft[cluster])")
    optimize.add_argument("--address", metavar="tcp://HOST:PORT", help="Dask scheduler address (--executor dask)")
    optimize.add_argument("--rrd", metavar="FILE.rrd", help="rerun recording: best eta per generation, the "
                          "population, and the best gait's motion")
    _add_force(optimize)
    _add_json(optimize, "the result")
    _add_quiet(optimize)
    _add_robot(optimize)
    _add_max_error(optimize)

    user = sub.add_parser("run", help="RFT on your own MuJoCo model: a joint driven through the medium",
                          description="Attach the granular RFT of Li, Zhang & Goldman 2013 to bodies of an MJCF "
                          "model and move one slide or hinge joint at constant speed (one stroke, or --set "
                          "drive.cycles=N back-and-forth cycles), exactly: the joint carries a very large armature "
                          "and the force (torque) it needs is recorded, with each attached body's position and the "
                          "medium's force on it. The scene (SI units) has [model] (path, bodies), [medium] (law, "
                          "name or zeta, surface_z, element_size), [drive] (joint, speed, stroke, cycles, start) and "
                          "[sim] (dt, integrator, backend, record_dt; MuJoCo's explicit step only).")
    user.add_argument("model", nargs="?", metavar="MODEL.xml", help="the MJCF file (overrides model.path)")
    ug = user.add_argument_group("scene")
    ug.add_argument("--scene", required=True, metavar="FILE.toml", help="user-model scene file in SI units")
    ug.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a scene key in SI units, e.g. --set drive.speed=0.05 (repeatable)")
    ug.add_argument("--backend", choices=("native", "python"), help="where the RFT force is computed (overrides "
                    "sim.backend)")
    _add_max_error(user)
    _add_run_outputs(user)

    intrude = sub.add_parser("intrude", help="a plate pushed vertically into the medium at several angles: the "
                             "force-depth curves of Li, Zhang & Goldman 2013",
                             description="Push a thin plate (plate.width x plate.length) at each angle beta "
                             "(0 horizontal, 90 vertical, cutting in edge first) straight down into the medium at "
                             "constant speed, from plate.clearance above the surface to plate.depth below it, and "
                             "record the medium's vertical and horizontal force against the depth of the plate's "
                             "lowest point.")
    intrude.add_argument("--angles", default="0,30,60,90", metavar="DEGS",
                         help="comma-separated plate angles in degrees, each in -90..90 (default: %(default)s)")
    ig = intrude.add_argument_group("scene")
    ig.add_argument("--scene", metavar="FILE.toml", help="intrusion scene file in SI units ([plate], [medium], "
                    "[sim]; default: the schema's defaults, a 25 x 38 mm plate to 50 mm in the generic medium)")
    ig.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a scene key in SI units, e.g. --set medium.zeta=0.5 (repeatable)")
    ig.add_argument("--backend", choices=("native", "python"), help="where the RFT force is computed")
    intrude.add_argument("--plot", metavar="FILE.png", help="write the force-depth curves as a figure")
    _add_force(intrude)
    _add_json(intrude, "each angle's summary and curve")
    _add_quiet(intrude)

    medium = sub.add_parser("medium", help="the catalogue of named granular media, with units and sources",
                            description="Print the named media of the catalogue (finrft/media.toml) that scenes "
                            "(medium.name) and `finrft law --medium` take: each value with its unit and source, "
                            "what is unverified, and what could not be found.")
    medium.add_argument("name", nargs="?", metavar="NAME", help="one medium (default: --list)")
    medium.add_argument("--list", action="store_true", help="every medium (the default)")
    _add_json(medium, "the media (each value with its unit and source)")
    _add_quiet(medium)

    law = sub.add_parser("law", help="a force law's stress map in a medium (li2013, rft3d: alpha_x, alpha_z over "
                         "beta, gamma; sandswim: F_perp, F_par over psi, gamma0)",
                         description="Evaluate a law's stress per unit depth over its angles, as in the "
                         "papers' figures: for li2013, alpha_x and alpha_z (N/cm^3) over the plate angle beta and "
                         "the velocity angle gamma, both -90..90 deg at 5 deg, for the medium's zeta; for rft3d the "
                         "same in the vertical plane (psi = 0) for the medium's xi_n (from its bulk density and "
                         "internal friction; generic: 1 N/cm^3); for sandswim, F_perp and F_par per unit C_S and "
                         "C_F over the angle psi between velocity and body axis (0..90 deg at 1 deg) and gamma0.")
    law.add_argument("name", metavar="NAME", help="the law: li2013, rft3d or sandswim")
    law.add_argument("--medium", default="generic", metavar="M",
                     help="a medium of the catalogue (finrft medium --list; default: %(default)s)")
    law.add_argument("--plot", metavar="FILE.png", help="write the map as a figure, one colour map per field")
    _add_force(law)
    law.add_argument("--json", action="store_true", help="print the map as JSON on the last line of "
                              "stdout: law, the two angle axes (_deg) and each field, flat lists of one entry per "
                              "grid point")
    _add_quiet(law)

    table = sub.add_parser("table", help="the paper's Table I: six gaits, eta next to the paper's",
                           description="Evaluate the six gaits of the paper's Table I (the preset's gait.cycles flap "
                           "cycles each, eta over the steady ones) and "
                           "print eta, the authors' script measure |net|/D1, D1, D2 and the net speed next to the "
                           "paper's eta_sim and eta_exp, as a Markdown table.")
    _add_workers(table)
    _add_json(table, "the rows")
    _add_quiet(table)
    _add_robot(table)
    _add_max_error(table)

    fitp = sub.add_parser("fit", help="fit plate-scene parameters to measured segment angles (CMA-ES)",
                          description="Fit plate-scene parameters so that simulated segment angles match measured "
                          "ones: each data file is a drag from flat at constant speed, 1 to 1000 mm/s (columns "
                          "time_s, displacement_mm, segment1_deg ...); the objective is the mean over files of the "
                          "mean squared error (deg^2), as the paper's E(b). The measurements shipped with finrft "
                          "are in the folder python -c 'import finrft.data as d; print(d.plate_drag_dir())' "
                          "prints.")
    fitp.add_argument("--data", nargs="+", metavar="FILE.csv", help="drag data to fit (required unless --resume)")
    fitp.add_argument("--validate", nargs="+", default=[], metavar="FILE.csv",
                      help="drag data to check the fit on, not fitted")
    fitp.add_argument("--params", metavar="NAMES",
                      help="comma-separated parameters: b (plate.damping), k (plate.stiffness), f_perp "
                           "(rft.f_perp), f_par (rft.f_par), or any numeric plate-scene key (default: b, the "
                           "paper's procedure)")
    fitp.add_argument("--bounds", action="append", default=[], metavar="KEY=LOW:HIGH",
                      help="bounds of a fitted parameter, by name or key, in mm for a length, deg for an angle, "
                           "else SI, e.g. b=0.0001:100, plate.segment_length=20:50 (defaults: b 0.01:100, k "
                           "0.01:100, f_perp and f_par 0.1:100 N and -2:2 N per segment of the paper plate, in "
                           "N/m^3); positive bounds over more than a decade are searched in log space")
    _add_search(fitp, "fit")
    _add_workers(fitp)
    _add_max_error(fitp)
    fitp.add_argument("--write-scene", metavar="OUT.toml", help="write the fitted scene (finrft drag --scene OUT.toml)")
    fitp.add_argument("--plot", metavar="OUT.png", help="simulated against measured angles for every file")
    fitp.add_argument("--rrd", metavar="FILE.rrd", help="rerun recording of the fitted drag of the first file")
    _add_force(fitp)
    _add_json(fitp, "the result")
    _add_quiet(fitp)
    _add_plate_scene(fitp)

    fitrft = sub.add_parser("fit-rft", help="identify RFT coefficients from rigid-plate forces",
                            description="Identify the paper law's f_perp and f_par (least squares) and the table "
                            "law's F_perp(theta), F_par(theta) from the steady forces on a rigid plate dragged at "
                            "several angles of attack (columns attack_deg, force_normal_N, force_tangential_N, as "
                            "written by finrft drag --plate rigid --forces-csv; one row per angle, with an angle "
                            "above 0 and one below 90 deg). Writes a scene fragment and the table CSV.")
    fitrft.add_argument("--data", required=True, metavar="FORCES.csv", help="forces per angle of attack")
    fitrft.add_argument("--speed", type=_number("mm/s"), default=30.0, metavar="MM_S",
                        help="drag speed of the measurements in mm/s (default: %(default)s)")
    fitrft.add_argument("--out", metavar="FRAGMENT.toml", help="write the [rft] scene fragment here "
                        "(default: print it)")
    fitrft.add_argument("--table", metavar="TABLE.csv", help="write the table law here (default: beside --out)")
    _add_force(fitrft)
    _add_json(fitrft, "the coefficients")
    _add_quiet(fitrft)
    _add_plate_scene(fitrft, backend=False)

    report = sub.add_parser("report", help="regenerate the paper's figures and table (Markdown, PNG, rerun)",
                            description="Write DIR/report.md with the paper's results regenerated: drag and rotate "
                            "forces, effective flapping, model against the plate-drag measurements, the robot's "
                            "Table I, optimisation and trajectories, and how long each part took; plus rerun "
                            "recordings. The files appear in DIR only when every part has succeeded.")
    report.add_argument("--out", default="report", metavar="DIR", help="output folder (default: %(default)s)")
    report.add_argument("--quick", action="store_true", help="a smaller version: fewer cycles and evaluations")
    report.add_argument("--preset", default="paper", choices=scenes.PRESETS[scenes.Scene],
                        help="plate preset fitted to the measurements (default: %(default)s)")
    report.add_argument("--data", metavar="DIR", help="folder of plate-drag measurements (default: those shipped "
                        "with finrft)")
    _add_workers(report)
    _add_force(report)
    _add_quiet(report)

    bench = sub.add_parser("bench", help="benchmarks, measured as ratios in one run on this machine")
    kinds = bench.add_subparsers(dest="bench", required=True, parser_class=_Parser)
    backends = kinds.add_parser("backends", help="Python callback vs native plugin vs bare MuJoCo, and batch",
                                description="Time the paper plate drag (200 mm at 30 mm/s) with each backend "
                                "against bare mj_step of the same model, and the throughput of a batch of drags "
                                "on all cores against one core.")
    backends.add_argument("--batch", type=_number("simulations", minimum=1, inclusive=True, integer=True),
                          default=64, metavar="N", help="simulations in the batch (default: %(default)s)")
    backends.add_argument("--scaling", metavar="FILE.png", help="also chart the batch throughput against the "
                          "number of workers (1, 2, ... up to the cores): process pool and threaded batch")
    _add_workers(backends)
    _add_force(backends)
    robot = kinds.add_parser("robot", help="one gait evaluation and a full optimisation",
                             description="Time one gait evaluation as the optimiser runs it (the preset's "
                             "gait.cycles flap cycles, eta over the steady ones), measure its eta against a converged "
                             "run of the same gait, and time a CMA-ES optimisation of --budget evaluations on all "
                             "cores, for a robot preset.")
    robot.add_argument("--preset", default="paper", choices=scenes.PRESETS[scenes.RobotScene],
                       help="robot preset (default: %(default)s)")
    robot.add_argument("--budget", type=_number("evaluations", minimum=1, inclusive=True, integer=True),
                       default=300, metavar="EVALS", help="optimisation budget (default: %(default)s)")
    _add_workers(robot)
    acc = kinds.add_parser("accuracy", help="speed against accuracy of every time-stepping method and step",
                           description="Run the origami drag (45 mm out and back) and one flap cycle of the "
                           "robot, each with the paper's and with physical inertias, for every method (explicit "
                           "with each MuJoCo integrator, implicit, newton: steps of 10 µs to 10 ms; adaptive and "
                           "adaptive-newton: tolerances 0.1 to 1e-5), v_reg (0.1, 1, 10 mm/s) and backend (python "
                           "at steps of 1 ms and more); write DIR/accuracy.csv, a chart of error against wall time "
                           "(accuracy.png) and a summary of the fastest setting within 0.1° and 1° (accuracy.md). "
                           "Takes about 4 minutes on two cores.")
    acc.add_argument("--out", default="accuracy", metavar="DIR", help="output folder (default: %(default)s)")
    acc.add_argument("--quick", action="store_true",
                     help="steps of 0.1 and 1 ms, one tolerance and v_reg, and a coarser reference (about 25 s)")
    _add_workers(acc)
    _add_force(acc)
    model = kinds.add_parser("modelling", help="what each modelling choice costs and changes",
                             description="Measure planar against 3D chains, rigid plates as one body against "
                             "welded segments, MuJoCo limit against penalty stops, and the half against the full "
                             "robot: the largest change in segment angle (deg), drive force (% of its peak) or "
                             "efficiency (points), and the wall-time ratio. About 10 s.")
    fitb = kinds.add_parser("fit", help="a 4-parameter plate fit over three drag files",
                            description="Time a fit of k, b, f_perp and f_par of the paper plate over three drag "
                            "files with --budget evaluations on all cores.")
    fitb.add_argument("--data", nargs="+", metavar="FILE.csv", help="drag data (default: the model's own drags "
                      "at 10, 30 and 50 mm/s)")
    fitb.add_argument("--budget", type=_number("evaluations", minimum=1, inclusive=True, integer=True),
                      default=300, metavar="EVALS", help="evaluations (default: %(default)s)")
    _add_workers(fitb)
    for kind in (backends, robot, model, fitb):
        _add_json(kind, "the figures")
    for kind in (backends, robot, acc, model, fitb):
        _add_quiet(kind)
    return parser


def _preset(args: argparse.Namespace) -> str:
    if args.scene and args.preset:
        raise UsageError(f"give --scene {args.scene} or --preset {args.preset}, not both")
    return args.preset or "paper"


def _resolve_scene(args: argparse.Namespace) -> scenes.Scene:
    overrides = dict(scenes.parse_override(item) for item in args.set)
    if getattr(args, "plate", None):
        overrides["plate.kind"] = args.plate
    if getattr(args, "backend", None):
        overrides["sim.backend"] = args.backend
    return scenes.load_scene(args.scene, preset_name=_preset(args), overrides=overrides)


def _resolve_robot(args: argparse.Namespace) -> scenes.RobotScene:
    overrides = dict(scenes.parse_override(item, scenes.RobotScene) for item in args.set)
    for flag, key in (("fin", "fin.kind"), ("model", "robot.model"), ("backend", "sim.backend")):
        if getattr(args, flag, None):
            overrides[key] = getattr(args, flag)
    for flag, key, scale in (("theta1", "gait.theta1", math.pi / 180), ("theta2", "gait.theta2", math.pi / 180),
                             ("arm_length", "arm.length", 1e-3), ("omega", "gait.omega", math.pi / 180)):
        if getattr(args, flag, None) is not None:
            overrides[key] = getattr(args, flag) * scale
    return scenes.load_scene(args.scene, preset_name=_preset(args), overrides=overrides, cls=scenes.RobotScene)


def _check_output(path: str | None, suffix: str, flag: str, force: bool, *, append: bool = False) -> None:
    """Refuse, before anything runs, an output file that cannot be written: the wrong suffix, a missing or
    read-only folder, a directory, or (unless ``force``, or ``append`` for files added to) an existing file."""
    if path is None:
        return
    target = Path(path)
    if target.suffix != suffix:
        raise UsageError(f"{flag} {path}: the file name must end in {suffix}")
    _check_writable(target.parent, flag, path)
    if target.is_dir():
        raise UsageError(f"{flag} {path} is a directory: give a file name")
    if target.exists() and not (force or append):
        raise UsageError(f"{flag} {path} exists: choose a new file, or pass --force to replace it")


def _check_output_dir(path: str, flag: str, force: bool) -> None:
    """The same for an output folder: it may exist, empty, or with ``force``."""
    target = Path(path)
    _check_writable(target.parent, flag, path)
    if target.exists() and not target.is_dir():
        raise UsageError(f"{flag} {path} is a file: give a folder")
    if target.is_dir() and any(target.iterdir()) and not force:
        raise UsageError(f"{flag} {path} exists and is not empty: choose a new folder, or pass --force to write "
                         f"into it")
    if target.is_dir():
        _check_writable(target, flag, path)


def _check_writable(folder: Path, flag: str, path: str) -> None:
    if not folder.is_dir():
        raise UsageError(f"{flag} {path}: {folder} is not a directory" if folder.exists() else
                         f"{flag} {path}: directory {folder} does not exist")
    try:  # a file made and removed, not os.access: that says yes to root, and to read-only file systems
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise UsageError(f"{flag} {path}: cannot write in {folder}: {exc.strerror}") from None


def _write_text(path: str, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _drive(args: argparse.Namespace) -> Drive:
    if args.command == "drag":
        if args.attack > 180:
            raise UsageError(f"argument --attack: must be within 0..180 degrees, got {args.attack:g}")
        return Drive("drag", args.speed / 1000, args.distance / 1000, args.cycles, args.attack)
    return Drive("rotate", math.radians(args.omega), math.radians(args.amplitude), args.cycles)


@contextlib.contextmanager
def _progress(args: argparse.Namespace, total: float, what: str,
              unit: str = "") -> Iterator[Callable[..., None] | None]:
    """A progress bar on stderr: yields ``update(done, note="")``, ``done`` counted towards ``total`` and never
    shown past it (``unit`` "%": ``done`` is a fraction of 1); None when stderr is not a terminal or with --quiet,
    so that the work skips its callbacks."""
    if args.quiet or not sys.stderr.isatty():
        yield None
        return
    from tqdm import tqdm
    scale = 100 if unit == "%" else 1
    form = "{desc}: {percentage:3.0f}% |{bar}| {elapsed}<{remaining}{postfix}" if unit == "%" else None
    try:  # a terminal that reports no size (0 x 0) would hide the bar
        size = os.get_terminal_size(sys.stderr.fileno())
    except (OSError, ValueError):
        size = os.terminal_size((0, 0))
    with tqdm(total=scale * total, desc=what, unit=unit or "it", file=sys.stderr, leave=False,
              ncols=size.columns or 80, nrows=size.lines or 24, bar_format=form) as bar:
        def update(done: float, note: str = "") -> None:
            if note:
                bar.set_postfix_str(note, refresh=False)
            bar.update(min(round(scale * done), bar.total) - bar.n)
        yield update


def _say(args: argparse.Namespace, text: str) -> None:
    """Human text on stdout, unless --quiet; it keeps a progress bar intact."""
    if not args.quiet:
        from tqdm import tqdm
        tqdm.write(text, file=sys.stdout)


def _steps(summary: dict[str, Any]) -> str:
    return f"{summary['steps']} steps taken ({summary['steps_rejected']} rejected)"


def _describe(run: Result, summary: dict[str, Any]) -> str:
    """A human-readable summary in the paper's units."""
    q, u = run.quantity, run.unit
    sim = run.scene.sim
    lines = [f"{run.drive.kind} of the {run.scene.plate.kind} plate, {sim.method} method (dt {sim.dt * 1e3:g} ms, "
             f"{sim.integrator}, {run.backend}): {_steps(summary)} in {run.wall_s:.2f} s",
             "final segment angles (deg): " + ", ".join(f"{a:.2f}" for a in summary["final_segment_angle_deg"]),
             "final hinge angles (deg):   " + ", ".join(f"{a:.2f}" for a in summary["final_hinge_angle_deg"]),
             f"peak drive {q}: {summary[f'peak_drive_{q}_{u}']:.4g} {u.replace('Nm', 'N m')}"]
    for i, row in enumerate(run.cycle_table(), start=1):
        lines.append(f"cycle {i}: mean {q} recovery {row[f'mean_recovery_{q}_{u}']:+.4g}, "
                     f"power {row[f'mean_power_{q}_{u}']:+.4g}; net impulse {row[f'net_impulse_{u}s']:+.4g} {u}s")
    lines.append(_error_line(run))
    return "\n".join(lines)


def _error_line(run: Any) -> str:
    # Any experiment's keys name their unit last (`experiment.Compared`): angle_deg, torque_Nm, eta_points, ...
    return (f"estimated discretisation error (companion run at {run.error_companion}): "
            + ", ".join(f"{what} {value:.2g} {unit.replace('Nm', 'N m')}" for (what, unit), value in
                        ((key.rsplit("_", 1), value) for key, value in run.error_estimate.items())))


def _run_test(args: argparse.Namespace) -> int:
    scene = _resolve_scene(args)
    _check_output(args.out, ".h5", "--out", args.force)
    _check_output(args.rrd, ".rrd", "--rrd", args.force)
    drive = _drive(args)
    forces_csv = getattr(args, "forces_csv", None)
    if forces_csv:
        from .fit import append_forces, check_forces_header, plate_forces
        if scene.plate.kind != "rigid":
            raise UsageError("--forces-csv needs a rigid plate (--plate rigid)")
        if drive.cycles is not None:
            raise UsageError("--forces-csv records the steady force of one stroke out: leave out --cycles")
        if drive.speed < 3 * scene.rft.v_reg:
            raise UsageError(f"--forces-csv needs a drag faster than 3 x rft.v_reg ({3e3 * scene.rft.v_reg:g} mm/s), "
                             f"where the rate-independent force is reached: got {1e3 * drive.speed:g} mm/s")
        _check_output(forces_csv, ".csv", "--forces-csv", args.force, append=True)
        check_forces_header(forces_csv)
    run = _run(args, PlateTest(drive), scene)
    if forces_csv:
        append_forces(forces_csv, plate_forces(run))
    summary = run.summary()
    _say(args, _describe(run, summary))
    _write(args, run)
    _said_written(args, (("forces", forces_csv),))
    if args.json:
        print(_json(summary))
    return 0


def _json(value: Any) -> str:
    """One line of strict JSON; a NaN or infinity anywhere is a failed result (exit 1), never invalid JSON."""
    try:
        return json.dumps(value, allow_nan=False,
                          default=lambda x: x.tolist() if isinstance(x, np.ndarray) else float(x))
    except ValueError:
        raise SimulationFailed("the result holds a NaN or infinite value: nothing is reported") from None


def _run(args: argparse.Namespace, experiment: Experiment, scene: Any) -> Result:
    """Run any experiment with the options every run takes (--max-error, the progress bar)."""
    with _progress(args, 1, experiment.name, "%") as bar:
        return run_experiment(experiment, scene, progress=bar, max_error=_limits(args))


def _write(args: argparse.Namespace, result: Result) -> None:
    """The files --out and --rrd ask for, of any experiment's result."""
    if args.out or args.rrd:
        from . import record  # h5py and rerun load only when a file is asked for
        if args.out:
            record.write_h5(result, args.out)
        if args.rrd:
            record.write_rrd(result, args.rrd)
    _said_written(args, (("HDF5", args.out), ("rerun recording", args.rrd)))


def _said_written(args: argparse.Namespace, files: Sequence[tuple[str, str | None]]) -> None:
    """One line for each file written, (what, path) with path None for one not asked for."""
    for what, path in files:
        if path:
            _say(args, f"wrote {what}: {path}")


def _swim(args: argparse.Namespace, scene: scenes.RobotScene) -> int:
    from .swim import Swim
    _check_output(args.out, ".h5", "--out", args.force)
    _check_output(args.rrd, ".rrd", "--rrd", args.force)
    run = _run(args, Swim(args.cycles or scene.gait.cycles), scene)
    summary = run.summary()
    _write(args, run)
    _say(args, f"{scene.robot.model} robot, {scene.fin.kind} fin, theta1 {summary['theta1_deg']:g} deg, theta2 "
         f"{summary['theta2_deg']:g} deg, arm {summary['arm_length_mm']:g} mm, omega {summary['omega_deg_s']:g} "
         f"deg/s, {scenes.resolution(scene.sim)} ({run.backend}): {_steps(summary)} in "
         f"{run.wall_s:.2f} s")
    for i, row in enumerate(run.cycle_table(), start=1):
        _say(args, f"cycle {i}: eta {100 * row['eta']:+.2f} %, forward D1 {row['D1_mm']:.2f} mm, back D2 "
             f"{row['D2_mm']:.2f} mm, net {row['net_mm']:+.2f} mm ({row['net_speed_mm_s']:+.3f} mm/s)")
    _say(args, _error_line(run))
    if args.json:
        print(_json(summary))
    return 0


def _overrides(args: argparse.Namespace, cls: type) -> dict[str, Any]:
    overrides = dict(scenes.parse_override(item, cls) for item in args.set)
    if args.backend:
        overrides["sim.backend"] = args.backend
    return overrides


def _user_run(args: argparse.Namespace) -> int:
    from .user_model import UserModel
    _check_output(args.out, ".h5", "--out", args.force)
    _check_output(args.rrd, ".rrd", "--rrd", args.force)
    overrides = _overrides(args, scenes.UserScene)
    if args.model:
        overrides["model.path"] = args.model
    scene = scenes.load_scene(args.scene, overrides=overrides, cls=scenes.UserScene)
    run = _run(args, UserModel.of(scene), scene)
    summary = run.summary()
    _write(args, run)
    q, u = run.quantity, run.unit.replace("Nm", "N m")
    sim = scene.sim
    _say(args, f"{scene.model.path}: joint {scene.drive.joint} driven, RFT on {', '.join(scene.model.bodies)} "
         f"({run.backend}; dt {sim.dt:g} s, {sim.integrator}): {_steps(summary)} in {run.wall_s:.2f} s")
    _say(args, f"mean drive {q} per stroke: " + ", ".join(
        f"{value:+.4g} {u}" for value in summary[f"mean_drive_{q}_{run.unit}_per_stroke"]))
    for body, position in summary["final_body_position_mm"].items():
        _say(args, f"{body}: final position (mm) " + ", ".join(f"{x:.2f}" for x in position))
    _say(args, _error_line(run))
    if args.json:
        print(_json(summary))
    return 0


def _angles(text: str) -> list[float]:
    try:
        angles = [float(a) for a in text.split(",") if a.strip()]
    except ValueError:
        raise UsageError(f"--angles expects comma-separated degrees, e.g. 0,30,60,90, got '{text}'") from None
    if not angles or not all(-90 <= a <= 90 for a in angles):
        raise UsageError(f"--angles: each angle must be within -90..90 degrees, got '{text}'")
    return angles


def _intrude(args: argparse.Namespace) -> int:
    from .intrusion import intrude, plot_curves
    _check_output(args.plot, ".png", "--plot", args.force)
    angles = _angles(args.angles)
    overrides = _overrides(args, scenes.IntrusionScene)
    scene = (scenes.load_scene(args.scene, overrides=overrides, cls=scenes.IntrusionScene) if args.scene else
             scenes.scene_from_dict({}, scenes.IntrusionScene).replace(**overrides))
    with _progress(args, 1, "intrude", "%") as bar:
        runs = intrude(scene, angles, progress=bar)
    if args.plot:
        with atomic_path(args.plot) as tmp:
            plot_curves(runs, tmp)
    for r in runs:
        s = r.summary()
        _say(args, f"beta {s['angle_deg']:g} deg: at {s['final_depth_mm']:.1f} mm, vertical force "
             f"{s['final_force_z_N']:.4g} N, horizontal {s['final_force_x_N']:+.4g} N")
    _said_written(args, (("figure", args.plot),))
    if args.json:
        print(_json([{**r.summary(), "depth_mm": 1e3 * r.depth, "force_z_N": r.force_z, "force_x_N": r.force_x}
                     for r in runs]))
    return 0


def _medium(args: argparse.Namespace) -> int:
    from . import media
    if args.name is not None and args.list:
        raise UsageError(f"give a medium's NAME ({args.name}) or --list, not both")
    chosen = (media.medium(args.name),) if args.name is not None else media.media()
    _say(args, "\n\n".join(media.describe(m) for m in chosen))
    if args.json:
        print(_json([m.to_dict() for m in chosen]))
    return 0


def _law(args: argparse.Namespace) -> int:
    from . import lawmap
    _check_output(args.plot, ".png", "--plot", args.force)
    data = lawmap.stress_map(args.name, args.medium)
    if args.plot:
        with atomic_path(args.plot) as tmp:
            lawmap.plot(args.name, args.medium, data, tmp)
    (xkey, x), (ykey, y), *fields = data.items()
    units = lawmap.law_module(args.name).MAP_UNITS
    _say(args, f"{args.name} in {args.medium}: {len(x)} points, {xkey} in [{x.min():g}, {x.max():g}], {ykey} in "
         f"[{y.min():g}, {y.max():g}]")
    for key, values in fields:
        _say(args, f"  {key}: {values.min():.4g} to {values.max():.4g} {units[key]}")
    if lawmap.note(args.name, args.medium):
        _say(args, f"  {lawmap.note(args.name, args.medium)}")
    _said_written(args, (("figure", args.plot),))
    if args.json:
        # the fields are in the law's map units (N/cm^3 for li2013), not SI: "units" names them
        print(_json({"law": args.name, "units": {key: units[key] for key in list(data)[2:]}, **data}))
    return 0


def _table(args: argparse.Namespace, scene: scenes.RobotScene) -> int:
    from .batch import run_experiments
    from .swim import PHYSICAL_FITTED, Swim, table_markdown, table_rows, table_scenes
    jobs = [(Swim(s.gait.cycles), s) for s in table_scenes(scene)]
    with _progress(args, len(jobs), "Table I", "gaits") as bar:
        runs = run_experiments(jobs, max_error=_limits(args), workers=args.workers,
                               progress=bar and (lambda done, total: bar(done)))
    rows = table_rows(runs, PHYSICAL_FITTED if args.preset == "physical" and not args.scene else ())
    if args.json:
        _say(args, table_markdown(rows))
        print(_json(rows))
    else:  # the table is what was asked for: --quiet leaves it
        print(table_markdown(rows))
    return 0


def _search_log(args: argparse.Namespace, fixed: dict[str, str]) -> str | None:
    """The log of an optimise or fit command, after checking --out and --resume; ``fixed``: the options (attribute
    -> flag) that a resumed run takes from its log, so that they may not be given with --resume."""
    if args.out and args.resume:
        raise UsageError("give either --out (a new log) or --resume (an existing one), not both")
    _check_output(args.out, ".h5", "--out", True)
    if args.out and Path(args.out).exists() and not args.force:
        raise UsageError(f"--out {args.out} exists: continue it with --resume {args.out}, choose a new file, or "
                         f"pass --force to replace it")
    if args.resume:
        if not Path(args.resume).is_file():
            raise UsageError(f"--resume {args.resume}: no such file")
        for name, flag in fixed.items():
            if getattr(args, name, None):
                raise UsageError(f"{flag} cannot be given with --resume: the log fixes it")
    return args.resume or args.out


def _interrupted(command: str, log: str | None, schema: str) -> "Interrupted":
    """Ctrl-C during a search: how far the log got and how to continue it."""
    from .optimize import read_log
    if log is None:
        return Interrupted("interrupted; nothing was logged (--out LOG.h5 makes a run resumable)")
    if not Path(log).is_file():
        return Interrupted("interrupted before the log was written")
    done = len(read_log(log, schema)["state/sigma"])
    return Interrupted(f"interrupted after {done} generation{'s' * (done != 1)}; continue with: finrft {command} "
                       f"--resume {shlex.quote(log)}")


def _fit(args: argparse.Namespace) -> int:
    from . import searchlog
    from .fit import ALIASES, drag_for, fit, fit_summary, logged_problem, plot, read_drag, resolve_params
    from .optimize import parse_bounds
    for path, suffix, flag in ((args.write_scene, ".toml", "--write-scene"), (args.plot, ".png", "--plot"),
                               (args.rrd, ".rrd", "--rrd")):
        _check_output(path, suffix, flag, args.force)
    log = _search_log(args, {"data": "--data", "params": "--params", "bounds": "--bounds", "scene": "--scene",
                             "set": "--set", "backend": "--backend"})
    if args.resume:
        scene, data, variables = logged_problem(args.resume)
    elif not args.data:
        raise UsageError("--data is required (or --resume LOG.h5)")
    else:
        scene = _resolve_scene(args)
        data = [read_drag(p) for p in args.data]
        names = [n.strip() for n in (args.params or "b").split(",") if n.strip()]
        variables = resolve_params(names, parse_bounds(args.bounds, scenes.Scene, ALIASES))
    validate = [read_drag(p) for p in args.validate]
    with _progress(args, args.budget, "fit", "evaluations") as bar:
        def on_generation(g: int, values: np.ndarray, extras: dict[str, np.ndarray], es: Any) -> None:
            if bar:
                bar(es.countevals, f"best RMSE {np.sqrt(es.best.f):.2f} deg")

        try:
            result = fit(scene, data, variables, budget=args.budget, seed=args.seed, validate=validate, log=log,
                         resume=bool(args.resume), workers=args.workers, max_error=_limits(args),
                         on_generation=on_generation)
        except KeyboardInterrupt:
            raise _interrupted("fit", log, searchlog.FIT) from None
    if args.write_scene:
        _write_text(args.write_scene, scenes.to_toml(result.scene))
    if args.plot:
        with atomic_path(args.plot) as tmp:
            plot(result.scene, [(d, "fitted") for d in data] + [(d, "validation") for d in validate], tmp)
    if args.rrd:
        from . import record
        record.write_rrd(simulate(result.scene, drag_for(data[0])), args.rrd)
    for key, value in result.search.best.items():
        _say(args, f"{key} = {value:.6g}")
    for label, table in (("fitted", result.rmse_deg), ("validation", result.validate_rmse_deg)):
        for name, rmse in table.items():
            _say(args, f"RMSE {name} ({label}): {rmse:.2f} deg")
    _say(args, f"{result.search.evaluations} evaluations in {result.search.wall_s:.1f} s")
    _said_written(args, (("search log", log), ("scene", args.write_scene), ("figure", args.plot),
                         ("rerun recording", args.rrd)))
    if args.json:
        print(_json(fit_summary(result)))
    return 0


def _fit_rft(args: argparse.Namespace) -> int:
    from . import geometry
    from .fit import identify_rft, read_forces, rft_fragment
    from .laws.table import write_table
    scene = _resolve_scene(args)
    table_path = args.table or (str(Path(args.out).with_suffix(".csv")) if args.out else None)
    _check_output(args.out, ".toml", "--out", args.force)
    _check_output(table_path, ".csv", "--table", args.force)
    forces = read_forces(args.data)
    law, table = identify_rft(forces, scene.plate.segments, scene.rft.v_reg, args.speed / 1000,
                              geometry.segment_scale(scene))
    fragment = rft_fragment(law, Path(table_path).name if table_path else "TABLE.csv")
    if table_path:
        with atomic_path(table_path) as tmp:
            write_table(tmp, table)
    if args.out:
        _write_text(args.out, fragment)
        _said_written(args, (("law", args.out), ("table", table_path)))
    else:
        print(fragment, end="")
    if args.json:
        print(_json({"f_perp": law.f_perp, "f_par": law.f_par, "v_reg": law.v_reg,
                     "table": {"attack_deg": table.attack_deg, "f_perp": table.f_perp, "f_par": table.f_par}}))
    return 0


def _optimize(args: argparse.Namespace, scene: scenes.RobotScene) -> int:
    from . import searchlog
    from .optimize import DEFAULT_VARIABLES, Variable, cli_values, logged_problem, optimize, parse_bounds, read_log
    _check_output(args.rrd, ".rrd", "--rrd", args.force)
    log = _search_log(args, {"bounds": "--bounds", "scene": "--scene", "set": "--set", "fin": "--fin",
                             "model": "--model", "backend": "--backend"})
    variables = {v.key: v for v in DEFAULT_VARIABLES}
    generations: list[tuple[np.ndarray, np.ndarray]] = []  # searched values (CLI units) and eta, for --rrd
    if args.resume:
        scene, logged = logged_problem(args.resume)
        variables = {v.key: v for v in logged}
        past = read_log(args.resume)
        generations = [(cli_values(scenes.RobotScene, list(variables), past["x"][past["generation"] == g]),
                        past["eta"][past["generation"] == g]) for g in range(len(past["state/sigma"]))]
    for key, (low, high) in parse_bounds(args.bounds, scenes.RobotScene).items():
        variables[key] = Variable(key, low, high)
    executor = None
    if args.executor == "dask":
        executor = _dask_executor(args.address)
    elif args.address:
        raise UsageError("--address goes with --executor dask")
    with _progress(args, args.budget, "optimize", "evaluations") as bar:
        def on_generation(g: int, values: np.ndarray, extras: dict[str, np.ndarray], es: Any) -> None:
            generations.append((cli_values(scenes.RobotScene, list(variables), values), extras["eta"]))
            if bar:
                best = np.nanmax([1 - c for c in es.fit.fit]) if len(es.fit.fit) else float("nan")
                bar(es.countevals, f"generation {g + 1}, best eta {100 * best:.2f} %")

        try:
            result = optimize(scene, variables=list(variables.values()), budget=args.budget, seed=args.seed,
                              log=log, resume=bool(args.resume), executor=executor, workers=args.workers,
                              max_error=_limits(args), on_generation=on_generation)
        except KeyboardInterrupt:
            raise _interrupted("optimize", log, searchlog.OPTIMIZE) from None
    from .swim import swim
    best_scene = scene.replace(**result.best)
    best = swim(best_scene, 1, max_error=_limits(args))
    if args.rrd:
        from . import record
        record.write_optimization_rrd(args.rrd, generations, list(variables), best)
    g = best_scene.gait
    eta = 1 - result.cost
    summary = {"theta1_deg": math.degrees(g.theta1), "theta2_deg": math.degrees(g.theta2),
               "arm_length_mm": 1e3 * best_scene.arm.length, "eta": eta, "best": result.best,
               "error_estimate": best.error_estimate, "error_companion": best.error_companion,
               "evaluations": result.evaluations, "generations": result.generations, "wall_s": result.wall_s,
               "seed": result.seed, "budget": result.budget, "stop": {k: str(v) for k, v in result.stop.items()}}
    _say(args, f"best eta {100 * eta:.2f} % at theta1 {summary['theta1_deg']:.1f} deg, theta2 "
         f"{summary['theta2_deg']:.1f} deg, arm {summary['arm_length_mm']:.1f} mm after {result.evaluations} "
         f"evaluations in {result.wall_s:.1f} s")
    _said_written(args, (("search log", log), ("rerun recording", args.rrd)))
    if args.json:
        print(_json(summary))
    return 0


def _dask_executor(address: str | None):
    if not address:
        raise UsageError("--executor dask needs --address tcp://HOST:PORT")
    try:
        from dask.distributed import Client
    except ImportError:
        raise UsageError("--executor dask needs Dask: pip install 'finrft[cluster]'") from None
    try:
        return Client(address, timeout="3s").get_executor()
    except (OSError, TimeoutError) as exc:
        raise UsageError(f"cannot reach the Dask scheduler at {address}: {exc}") from None


def _scene(args: argparse.Namespace) -> int:
    if args.scene and args.dump:
        raise UsageError(f"give --scene {args.scene} or --dump {args.dump}, not both")
    kind = scenes.RobotScene if args.robot else scenes.Scene
    overrides = dict(scenes.parse_override(item, kind) for item in args.set)
    resolved = scenes.load_scene(args.scene, preset_name=args.dump or "paper", overrides=overrides, cls=kind)
    print(scenes.to_toml(resolved), end="")
    return 0


def _report(args: argparse.Namespace) -> int:
    from .report import write_report
    _check_output_dir(args.out, "--out", args.force)
    with _progress(args, 1, "report", "%") as bar:
        path = write_report(args.out, quick=args.quick, workers=args.workers, data_dir=args.data,
                            plate=scenes.preset(args.preset),
                            progress=bar and (lambda done, total, part: bar(done / total, part)))
    _said_written(args, (("report", path),))
    return 0


def _bench(args: argparse.Namespace) -> int:
    from . import bench
    log = lambda text: _say(args, text)  # noqa: E731
    if args.bench == "accuracy":
        _check_output_dir(args.out, "--out", args.force)
        with _progress(args, 1, "bench accuracy", "%") as bar:
            bench.accuracy(args.out, quick=args.quick, workers=args.workers, log=log,
                           progress=bar and (lambda done, total: bar(done / total)))
        return 0
    if args.bench == "fit":
        with _progress(args, args.budget, "bench fit", "evaluations") as bar:
            figures = bench.fit_speed(args.data, budget=args.budget, workers=args.workers, log=log,
                                      progress=bar and (lambda done, total: bar(done)))
    else:
        if args.bench == "backends":
            _check_output(args.scaling, ".png", "--scaling", args.force)
        run = {"modelling": lambda **kw: bench.modelling(**kw),
               "robot": lambda **kw: bench.robot(scenes.preset(args.preset, scenes.RobotScene), budget=args.budget,
                                                 workers=args.workers, **kw),
               "backends": lambda **kw: bench.backends(batch_size=args.batch, workers=args.workers, **kw)}
        with _progress(args, 1, f"bench {args.bench}", "%") as bar:
            figures = run[args.bench](log=log, progress=bar and (lambda done, total: bar(done / total)))
        if args.bench == "backends" and args.scaling:
            figures["scaling"] = bench.scaling(args.scaling, batch_size=args.batch, measured=figures,
                                               log=log)["rows"]
            _said_written(args, (("figure", args.scaling),))
    if args.json:
        print(_json(figures))
    return 0


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"finrft: warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    with warnings.catch_warnings():
        warnings.showwarning = _one_line_warning
        try:
            status = _main(parser, argv)
            sys.stdout.flush()  # a reader that went away shows here, not as a traceback at exit
            return status
        except BrokenPipeError:
            # stdout was closed early (finrft swim --json | head): stop quietly, as Unix tools do on SIGPIPE.
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 141
        except KeyboardInterrupt:
            print("finrft: interrupted", file=sys.stderr)
            return 130


def _robot(command: Callable[[argparse.Namespace, scenes.RobotScene], int]) -> Callable[[argparse.Namespace], int]:
    return lambda args: command(args, _resolve_robot(args))


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "drag": _run_test, "rotate": _run_test, "scene": _scene, "swim": _robot(_swim), "optimize": _robot(_optimize),
    "table": _robot(_table), "run": _user_run, "intrude": _intrude, "medium": _medium, "law": _law, "fit": _fit,
    "fit-rft": _fit_rft, "report": _report, "bench": _bench}


def _main(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> int:
    try:
        args = parser.parse_args(argv)
        return COMMANDS[args.command](args)
    except (UsageError, scenes.SceneError) as exc:
        print(f"finrft: error: {exc}", file=sys.stderr)
        return 2
    except SimulationFailed as exc:
        print(f"finrft: error: {exc}", file=sys.stderr)
        return 1
    except Interrupted as exc:
        print(f"finrft: {exc}", file=sys.stderr)
        return 130
    except BrokenPipeError:
        raise
    except OSError as exc:  # a file that could not be read or written after the checks (disk full, removed)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"finrft: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
