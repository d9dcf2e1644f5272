"""Builds the tempokey package with its tempokey.v1 stubs generated from the repository's protos.

The stubs are generated while the package is built (build_py), into the build tree, by the same
tools and from the same protos as the C++ build's Python stubs (client/python/CMakeLists.txt):
protoc with grpc_python_plugin (Debian's protobuf-compiler and protobuf-compiler-grpc), or,
when that plugin is missing, `python3 -m grpc_tools.protoc` if its libprotoc is 3.15 or newer
(older ones refuse proto3 `optional`). Environment overrides, set by the build's tests so both
use exactly the programs CMake found:
  TEMPOKEY_PROTO_DIR            the folder holding tempokey/v1/*.proto (default ../../proto)
  TEMPOKEY_PROTOC               protoc
  TEMPOKEY_GRPC_PYTHON_PLUGIN   grpc_python_plugin
The version is the project's, read from ../../CMakeLists.txt. Build options keep the source
tree clean: build files go to a temporary folder, not beside this file.
"""

import atexit
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import List

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
CHECKOUT = HERE.parent.parent
MIN_GRPC_TOOLS_PROTOC = (3, 15)


def project_version() -> str:
    text = (CHECKOUT / "CMakeLists.txt").read_text(encoding="utf-8")
    found = re.search(r"project\(\s*tempokey\s+VERSION\s+([0-9.]+)", text)
    if found is None:
        raise SystemExit("setup.py: no `project(tempokey VERSION x.y.z)` in %s"
                         % (CHECKOUT / "CMakeLists.txt"))
    return found.group(1)


def proto_dir() -> Path:
    folder = Path(os.environ.get("TEMPOKEY_PROTO_DIR") or CHECKOUT / "proto")
    if not (folder / "tempokey" / "v1").is_dir():
        raise SystemExit("setup.py: %s has no tempokey/v1/*.proto; build from a tempokey "
                         "checkout or set TEMPOKEY_PROTO_DIR" % folder)
    return folder


def grpc_tools_protoc_version() -> tuple:
    run = subprocess.run([sys.executable, "-m", "grpc_tools.protoc", "--version"],
                         capture_output=True, text=True, check=False)
    found = re.search(r"libprotoc (\d+)\.(\d+)", run.stdout) if run.returncode == 0 else None
    return (int(found.group(1)), int(found.group(2))) if found else ()


def generator() -> List[str]:
    """The command that generates the stubs, as CMake chooses it."""
    protoc = os.environ.get("TEMPOKEY_PROTOC") or shutil.which("protoc")
    plugin = os.environ.get("TEMPOKEY_GRPC_PYTHON_PLUGIN") or shutil.which("grpc_python_plugin")
    if protoc and plugin:
        return [protoc, "--plugin=protoc-gen-grpc_python=%s" % plugin]
    version = grpc_tools_protoc_version()
    if version and version >= MIN_GRPC_TOOLS_PROTOC:
        return [sys.executable, "-m", "grpc_tools.protoc"]
    raise SystemExit("setup.py: cannot generate the tempokey.v1 stubs: install protobuf-compiler "
                     "and protobuf-compiler-grpc (protoc and grpc_python_plugin)")


def generate_stubs(out_dir: Path) -> None:
    protos = proto_dir()
    sources = sorted(str(p) for p in (protos / "tempokey" / "v1").glob("*.proto"))
    out_dir.mkdir(parents=True, exist_ok=True)
    subprocess.run(generator() + ["--proto_path=%s" % protos, "--python_out=%s" % out_dir,
                                  "--grpc_python_out=%s" % out_dir] + sources, check=True)
    stubs = out_dir / "tempokey" / "v1"
    (stubs / "__init__.py").write_text('"""tempokey.v1 messages and stubs, generated at build '
                                       'time from proto/tempokey/v1/*.proto."""\n')


class BuildPyWithStubs(build_py):
    """build_py, then the tempokey.v1 stubs generated into the same build folder."""

    def run(self) -> None:
        super().run()
        generate_stubs(Path(self.build_lib))


SCRATCH = tempfile.mkdtemp(prefix="tempokey-python-build-")
atexit.register(shutil.rmtree, SCRATCH, ignore_errors=True)

setup(
    version=project_version(),
    cmdclass={"build_py": BuildPyWithStubs},
    options={"build": {"build_base": os.path.join(SCRATCH, "build")},
             "egg_info": {"egg_base": SCRATCH}},
)
