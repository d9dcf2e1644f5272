"""Installs client/python into a fresh virtual environment, as a user would, for the Python tests.

    install_package.py --python PYTHON --venv DIR --package client/python

Removes DIR, creates it with `PYTHON -m venv --system-site-packages` (so Debian's python3-grpcio
and python3-protobuf are visible), then runs `pip install --no-index --no-build-isolation
PACKAGE` in it: no network, the build tools from Debian (python3-setuptools, python3-wheel).
The stub generator is the one the C++ build found when the environment names it
(TEMPOKEY_PROTOC, TEMPOKEY_GRPC_PYTHON_PLUGIN; see client/python/setup.py). Exits non-zero with
pip's output when anything fails. Run by CTest as the setup of the `python` tests.
"""

import argparse
import os
import shutil
import subprocess
import sys

STEP_TIMEOUT_SECONDS = 300


def run(command):
    print("+ " + " ".join(command), flush=True)
    done = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                          timeout=STEP_TIMEOUT_SECONDS, check=False)
    print(done.stdout, flush=True)
    if done.returncode != 0:
        sys.exit("failed (exit %d): %s" % (done.returncode, " ".join(command)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", required=True)
    parser.add_argument("--venv", required=True)
    parser.add_argument("--package", required=True)
    args = parser.parse_args()

    shutil.rmtree(args.venv, ignore_errors=True)
    run([args.python, "-m", "venv", "--system-site-packages", args.venv])
    pip = [os.path.join(args.venv, "bin", "python"), "-m", "pip"]
    run(pip + ["install", "--no-index", "--no-build-isolation", "--no-cache-dir",
               "--disable-pip-version-check", args.package])
    return 0


if __name__ == "__main__":
    sys.exit(main())
