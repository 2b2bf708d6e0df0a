"""Builds the Python package `octocd` with the project's CMake build (pyproject.toml).

`pip install --no-build-isolation .` (docs/install.md) runs this: CMake configures the
project in build-pip/cmake (OCTOCD_PYTHON=ON for this interpreter, no tests), builds only
the target `octocd_python` (the extension octocd._octocd and the package's .py files, laid
out in build-pip/cmake/python/octocd/) and the wheel takes that folder. Extra CMake
arguments: the CMAKE_ARGS environment variable (e.g. "-DOCTOCD_CUDA=OFF"), as other
CMake-driven Python builds read it. Parallel jobs: CMAKE_BUILD_PARALLEL_LEVEL (CMake's own).
"""
import os
import shlex
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

HERE = os.path.dirname(os.path.abspath(__file__))
os.makedirs(os.path.join(HERE, "build-pip"), exist_ok=True)  # egg_info and the wheel are built there


class CMakeExtension(Extension):
    """The extension octocd._octocd, built by CMake rather than by setuptools."""

    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    """Configures and builds the CMake target octocd_python, then copies the built package."""

    def build_extension(self, ext):
        cmake = shutil.which("cmake")
        if cmake is None:
            sys.exit("octocd: cmake not found; install Debian's cmake (scripts/install-deps.sh)")
        build_dir = os.path.join(HERE, "build-pip", "cmake")
        args = [cmake, "-S", HERE, "-B", build_dir, "-DCMAKE_BUILD_TYPE=Release", "-DOCTOCD_PYTHON=ON",
                "-DOCTOCD_BUILD_TESTS=OFF", f"-DPython3_EXECUTABLE={sys.executable}"]
        if shutil.which("ninja"):
            args += ["-G", "Ninja"] if not os.path.exists(os.path.join(build_dir, "CMakeCache.txt")) else []
        args += shlex.split(os.environ.get("CMAKE_ARGS", ""))
        subprocess.run(args, check=True)
        subprocess.run([cmake, "--build", build_dir, "--target", "octocd_python"], check=True)
        built = os.path.join(build_dir, "python", "octocd")
        dest = os.path.dirname(os.path.abspath(self.get_ext_fullpath(ext.name)))
        os.makedirs(dest, exist_ok=True)
        for name in os.listdir(built):
            if name.endswith(".so"):
                shutil.copy2(os.path.join(built, name), os.path.join(dest, name))


setup(
    ext_modules=[CMakeExtension("octocd._octocd")],
    cmdclass={"build_ext": CMakeBuild},
    options={"build": {"build_base": "build-pip"}, "egg_info": {"egg_base": "build-pip"}},
)
