"""The compiled kernels (swarmbed/kernels/_compiled.pyx); everything else is in pyproject.toml.

Built with ``-ffp-contract=off``: a compiler that fused a*b+c into one rounding would give other
bits than the Python reference (and than another CPU). ``optional=True``: where no C compiler is
found, the install goes on and the package runs the reference (swarmbed.kernels says so)."""

from setuptools import Extension, setup

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
                optional=True,
            )
        ],
        compiler_directives={"language_level": 3},
        quiet=True,
    )

setup(ext_modules=extensions)
