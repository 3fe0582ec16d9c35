"""Build the native RFT plugin (plugins/finrft_rft.c) against the pinned MuJoCo wheel's headers and library.

The plugin is a plain shared library, not a Python extension module: MuJoCo loads it and it registers itself.
"""

import glob
import os

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

LIBRARY = "libfinrft_rft.so"


class BuildPlugin(build_ext):
    def build_extensions(self):
        import mujoco  # the build requirement pins the same version as the runtime dependency

        root = os.path.dirname(mujoco.__file__)
        # The wheel ships only the versioned libmujoco.so.X.Y.Z, so link the file itself.
        (library,) = glob.glob(os.path.join(root, "libmujoco.so.*"))
        for ext in self.extensions:
            ext.include_dirs.append(os.path.join(root, "include"))
            ext.extra_objects.append(library)
        super().build_extensions()

    def get_export_symbols(self, ext):
        return []

    def get_ext_filename(self, fullname):
        return os.path.join(*fullname.split(".")[:-1], LIBRARY)


setup(
    ext_modules=[Extension("finrft.libfinrft_rft", sources=["plugins/finrft_rft.c"],
                           extra_compile_args=["-O2", "-std=c99", "-Wall", "-Wextra", "-Wno-unused-parameter"],
                           extra_link_args=["-lm", "-Wl,-rpath,$ORIGIN/../mujoco"])],
    cmdclass={"build_ext": BuildPlugin},
)
