"""Build the native RFT plugin (plugins/: the plugin, its laws and its steppers) against the headers and library of
the `mujoco` package.

The plugin is a plain shared library, not a Python extension module: MuJoCo loads it and it registers itself. It is
linked the way MuJoCo's own plugins are, against the library the `mujoco` wheel ships (libmujoco.so.X.Y.Z on Linux,
libmujoco.X.Y.Z.dylib on macOS, mujoco.dll on Windows), and at run time binds to the one `import mujoco` loaded or
finds it relative to itself (finrft/ and mujoco/ are installed side by side): no path of the build machine ends up
in the library.
"""

import importlib.util
import re
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


def _native():
    """finrft/native.py, read on its own (it imports only the standard library): the library's name and MuJoCo's
    version format have their one definition there."""
    spec = importlib.util.spec_from_file_location("finrft_native", Path(__file__).parent / "finrft" / "native.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


native = _native()


def mujoco_root() -> Path:
    # Found, not imported: importing mujoco runs every installed plugin entry point, finrft's own included.
    spec = importlib.util.find_spec("mujoco")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("building finrft needs the mujoco package (a build requirement in pyproject.toml)")
    return Path(next(iter(spec.submodule_search_locations)))


def header_version(include: Path) -> int:
    match = re.search(r"^#define\s+mjVERSION_HEADER\s+(\d+)", (include / "mujoco" / "mujoco.h").read_text(), re.M)
    return int(match.group(1))


def windows_import_library(compiler, include: Path, out: Path, plat_name: str) -> Path:
    """mujoco.lib for MSVC's linker, made from the functions the headers export: the wheel ships only mujoco.dll."""
    names = sorted({name for header in sorted((include / "mujoco").glob("*.h"))
                    for name in re.findall(r"^MJAPI\s+(?!extern)[^;(]*?\b(\w+)\s*\(", header.read_text(), re.M)})
    out.mkdir(parents=True, exist_ok=True)
    definition = out / "mujoco.def"
    definition.write_text("LIBRARY mujoco.dll\nEXPORTS\n" + "".join(f"  {name}\n" for name in names))
    if not compiler.initialized:
        compiler.initialize()
    machine = {"win-amd64": "X64", "win-arm64": "ARM64", "win32": "X86"}[plat_name]
    library = out / "mujoco.lib"
    compiler.spawn([compiler.lib, "/nologo", f"/DEF:{definition}", f"/OUT:{library}", f"/MACHINE:{machine}"])
    return library


class BuildPlugin(build_ext):
    def build_extensions(self):
        root = mujoco_root()
        include = root / "include"
        version = header_version(include)
        for ext in self.extensions:
            ext.include_dirs.append(str(include))
            if self.compiler.compiler_type == "msvc":
                # No rpath on Windows: MuJoCo's Python package loads mujoco.dll first, and Windows resolves the
                # plugin's import of mujoco.dll to the module already loaded.
                ext.extra_objects.append(str(windows_import_library(self.compiler, include, Path(self.build_temp),
                                                                    self.plat_name)))
                continue
            # -g0 overrides Python's -g: debug information would carry the build directory (MuJoCo ships none).
            # Hidden by default: the C files share functions among themselves, the library exports only FINRFT_EXPORT.
            # -fno-math-errno: no C file reads errno, and without it every sqrt carries a branch to the library's
            # (the same numbers: IEEE square roots either way).
            ext.extra_compile_args += ["-O3", "-g0", "-std=c99", "-Wall", "-Wextra", "-Wno-unused-parameter",
                                       "-fvisibility=hidden", "-fno-math-errno"]
            if sys.platform == "darwin":
                # The plugin records libmujoco's install name, @rpath/mujoco.framework/.../libmujoco.X.Y.Z.dylib,
                # which dyld matches to the library `import mujoco` has loaded, as for MuJoCo's own plugins in the
                # wheel; the rpath finds the file should a release name it @rpath/libmujoco.X.Y.Z.dylib instead.
                ext.extra_objects.append(str(root / f"libmujoco.{native.version_text(version)}.dylib"))
                ext.extra_link_args += ["-Wl,-rpath,@loader_path/../mujoco",
                                        f"-Wl,-install_name,@rpath/{native.LIBRARY}"]
            else:
                ext.extra_objects.append(str(root / f"libmujoco.so.{native.version_text(version)}"))
                ext.extra_link_args += ["-lm", "-Wl,-rpath,$ORIGIN/../mujoco"]
        if self.compiler.compiler_type != "msvc":
            self.compiler.set_executable("linker_so", plugin_linker(self.compiler.linker_so))
        # A library left in build/ by an earlier install may be for another MuJoCo: always compile (a few files).
        self.force = True
        super().build_extensions()

    def get_export_symbols(self, ext):
        return []  # the C file marks its own exports; a Python module's PyInit_ symbol does not exist here

    def get_ext_filename(self, fullname):
        return str(Path(*fullname.split(".")[:-1], native.LIBRARY))


def plugin_linker(python_linker: list[str]) -> list[str]:
    """Python's command for linking extension modules, made fit for a plain shared library.

    Python's own link flags can carry an rpath to the build machine's Python (pyenv and similar builds add
    -Wl,-rpath,<prefix>/lib), which the plugin does not need; on macOS they make a bundle, where MuJoCo's plugins
    are dynamic libraries.
    """
    kept = [arg for arg in python_linker if not re.match(r"-Wl,(-rpath|-R)", arg)]
    return ["-dynamiclib" if arg == "-bundle" else arg for arg in kept]


def plugin_extension() -> Extension:
    """The library: the segment plugin, the steppers (and peaks.c, those that keep a drive's peak load), every
    segment law in plugins/laws/ (which the plugin finds by the list of names given as FINRFT_LAWS), every kind of
    free surface in plugins/surfaces/ (finrft.surfaces' twins), the surface
    plugin of finrft.attach and the guard of its Python backend; the steppers' return codes come from
    finrft/native.py."""
    laws = sorted(Path("plugins", "laws").glob("*.c"))
    surfaces = sorted(Path("plugins", "surfaces").glob("*.c"))
    macros = [("FINRFT_LAWS", "".join(f"X({law.stem})" for law in laws))]
    macros += [(f"FINRFT_{code.name}", str(int(code))) for code in native.Code]
    return Extension("finrft.libfinrft_rft", sources=["plugins/finrft_rft.c", "plugins/steppers.c", "plugins/peaks.c",
                                                      "plugins/finrft_surface.c", "plugins/finrft_guard.c",
                                                      *(law.as_posix() for law in laws),
                                                      *(surface.as_posix() for surface in surfaces)],
                     depends=["plugins/finrft.h", "plugins/surfaces/surfaces.h"], define_macros=macros)


setup(
    ext_modules=[plugin_extension()],
    cmdclass={"build_ext": BuildPlugin},
)
