#!/usr/bin/env python3
"""Install the system tools the Makefile needs: make, g++, iverilog, and the lz4 library
that Verilator's FST waveform writer links (``--waves --sim verilator``).

Run with the system Python on a fresh machine, before ``make``. As root it installs what is
missing with apt; otherwise it names what to install. It changes nothing when all is there.
"""

import os
import shutil
import subprocess
import sys

NEEDED = {"make": "make", "g++": "g++", "iverilog": "iverilog"}
#: Files (any of each tuple) standing for a library package.
NEEDED_FILES = {"liblz4-dev": ("/usr/include/lz4.h",)}


def main() -> int:
    if sys.version_info < (3, 11):
        print(f"bootstrap: Python 3.11 or newer is needed, this is {sys.version.split()[0]}",
              file=sys.stderr)
        return 1
    missing = [pkg for tool, pkg in NEEDED.items() if shutil.which(tool) is None]
    missing += [pkg for pkg, files in NEEDED_FILES.items()
                if not any(os.path.exists(f) for f in files)]
    if not missing:
        return 0
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        print("bootstrap: missing " + ", ".join(missing) + ". Install them, for example: "
              "sudo apt-get install " + " ".join(missing), file=sys.stderr)
        return 1
    print("bootstrap: installing " + " ".join(missing) + " with apt-get", file=sys.stderr)
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    subprocess.run(["apt-get", "update", "-qq"], check=True, env=env)
    subprocess.run(["apt-get", "install", "-y", "-qq", *missing], check=True, env=env)
    still = [tool for tool in NEEDED if shutil.which(tool) is None]
    still += [pkg for pkg, files in NEEDED_FILES.items()
              if not any(os.path.exists(f) for f in files)]
    if still:
        print("bootstrap: still missing after apt-get: " + ", ".join(still), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
