# SPDX-License-Identifier: Apache-2.0
# Copyright 2026 pneumatic_unload maintainers
"""ament_python package definition of pneumatic_unload (colcon and pip both use it)."""

import hashlib
import os
from glob import glob
from pathlib import Path

from setuptools import Extension, find_packages, setup
from setuptools.command.build_ext import build_ext

PACKAGE = "pneumatic_unload"

def _kernel(source: str) -> Extension:
    """The C source ``source`` built into ``_<stem>.so.0`` beside it when the package is
    built or installed (loaded through ctypes, model/kernel.py), the hash of its text
    compiled in: nothing is compiled at run time."""
    path = Path(source)
    sha = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
    module = ".".join((*path.parent.parts, f"_{path.stem}"))
    return Extension(module, sources=[source], libraries=["m"],
                     extra_compile_args=["-O2", "-std=c99"],
                     define_macros=[("PU_SOURCE_SHA", f'"{sha}"')])


#: File name suffix of the compiled C libraries: a shared library's (loaded through
#: ctypes), not a Python extension module's (pkgutil and importers do not list it).
LIBRARY_SUFFIX = ".so.0"


class BuildKernels(build_ext):
    """build_ext naming the C libraries ``_<stem>.so.0`` (not importable modules)."""

    def get_ext_filename(self, fullname: str) -> str:
        return os.path.join(*fullname.split(".")) + LIBRARY_SUFFIX


setup(
    name=PACKAGE,
    cmdclass={"build_ext": BuildKernels},
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    # the model's C kernel and the estimator's crossing fit: compiled by the build
    # (ext_modules); the sources ship too (an edited source is rebuilt: model/kernel.py)
    ext_modules=[_kernel(f"{PACKAGE}/model/kernel.c"),
                 _kernel(f"{PACKAGE}/estimation/regression.c")],
    package_data={f"{PACKAGE}.model": ["kernel.c"], f"{PACKAGE}.estimation": ["regression.c"],
                  # the results database's Alembic revisions, run when it is opened
                  f"{PACKAGE}.testline": ["migrations/*.py", "migrations/versions/*.py"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml"))),
        # ros2 launch pneumatic_unload bench.launch.yaml
        (f"share/{PACKAGE}/launch", sorted(glob("launch/*.launch.yaml"))),
        # a Foxglove Studio layout: pressure, p*, the crossing and the estimates
        (f"share/{PACKAGE}/foxglove", sorted(glob("foxglove/*.json"))),
        # the reference bags (bags/README.md): ros2 bag play, pneumatic-unload analyze
        *[(f"share/{PACKAGE}/bags/{Path(d).name}", sorted(glob(f"{d}/*")))
          for d in sorted(glob("bags/*/"))],
        (f"share/{PACKAGE}/bags", ["bags/README.md"]),
        (f"share/{PACKAGE}", ["LICENSE", "CHANGELOG.rst"]),
        # the command line on PATH once a colcon workspace is sourced (the console
        # scripts go to lib/{PACKAGE}, where ros2 run finds them)
        ("bin", ["bin/pneumatic-unload"]),
    ],
    install_requires=["setuptools", "numpy", "scipy", "PyYAML", "matplotlib", "rosbags",
                      "mcap", "mcap-ros2-support", "SQLAlchemy>=2.0", "alembic", "psutil",
                      "tqdm"],
    # colcon test runs pytest with these (extras_require, not tests_require: colcon reads
    # this one); package.xml's test_depend keys are the same
    extras_require={"test": ["pytest", "hypothesis"],
                    # the OPC UA bridge (no rosdep key: pip install asyncua)
                    "opcua": ["asyncua"]},
    zip_safe=False,
    maintainer="pneumatic_unload maintainers",
    maintainer_email="maintainers@pneumatic-unload.invalid",
    description="Sonic conductance of pneumatic components from a tank discharge (ROS 2).",
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            f"estimator = {PACKAGE}.nodes.estimator:main",
            f"simulator = {PACKAGE}.nodes.simulator:main",
            f"recorder = {PACKAGE}.nodes.recorder:main",
            f"replay = {PACKAGE}.nodes.replay:main",
            f"opcua = {PACKAGE}.nodes.opcua:main",
            f"pneumatic-unload = {PACKAGE}.app.cli:main",
        ],
    },
)
