"""The joint histogram's compiled pass (stages/registration/_histogram.c: plain C and POSIX threads, no numpy
headers), the one compiled part of topomatch; everything else is in pyproject.toml. Optional: without a C
compiler the build skips it and the registration computes the same histograms in numpy (slower)."""

from setuptools import Extension, setup

setup(ext_modules=[Extension("topomatch.stages.registration._histogram", ["stages/registration/_histogram.c"],
                             optional=True)])
