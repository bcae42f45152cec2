"""The compiled kernels (swarmbed/kernels/_compiled.pyx); everything else is in pyproject.toml.

Built with ``-ffp-contract=off``: a compiler that fused a*b+c into one rounding would give other
bits than the Python reference (and than another CPU). Where they cannot be built (no C compiler,
no Python headers, no Cython), the install goes on without them and the package runs the Python
reference, with the same results (swarmbed.kernels says so when a run starts)."""

import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext


class OptionalBuildExt(build_ext):
    """build_ext that reports a failure to compile and goes on: the kernels are a speed-up only."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as exc:  # noqa: BLE001 (any failure to build leaves the Python reference)
            print(
                f"swarmbed: the compiled kernels were not built ({exc}); running their Python reference",
                file=sys.stderr,
            )

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except Exception as exc:  # noqa: BLE001
            print(f"swarmbed: {ext.name} was not built ({exc}); running its Python reference", file=sys.stderr)


try:
    from Cython.Build import cythonize
except ImportError:  # no Cython (an install without build isolation): the Python reference only
    extensions = []
else:
    extensions = cythonize(
        [
            Extension(
                "swarmbed.kernels._compiled",
                ["swarmbed/kernels/_compiled.pyx"],
                extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
            )
        ],
        compiler_directives={"language_level": 3},
        quiet=True,
    )

setup(ext_modules=extensions, cmdclass={"build_ext": OptionalBuildExt})
