"""Make the ROS 2 wheels' CMake files usable for building a message package in this prefix.

The ros-kilted-* wheels are built in a manylinux container: their `export_*__rosidl_generator_pyExport.cmake`
files name that container's Python and NumPy include folders (/opt/python/cp311-cp311/...), which do not exist
here, and CMake refuses an imported target whose include folder is missing. This rewrites those two paths to
this interpreter's own (sysconfig, numpy.get_include()) and refuses anything else it does not know, so a new
wheel's surprise stops the build with its name. Idempotent; each file is replaced atomically.

    python tools/wheel_cmake.py PREFIX     (PREFIX: the venv holding the wheels, e.g. .venv)
"""

from __future__ import annotations

import os
import re
import sys
import sysconfig
import tempfile
from pathlib import Path

CONTAINER_PYTHON = re.compile(r"/opt/python/cp3\d+-cp3\d+/include/python3\.\d+")
CONTAINER_NUMPY = re.compile(r"/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/_core/include")
CONTAINER_ANY = re.compile(r"/opt/python/[^;\"\s)]*")


def local_includes() -> tuple[str, str]:
    """This interpreter's C headers and NumPy's, as the generated Python type support compiles against them."""
    import numpy

    python = sysconfig.get_paths()["include"]
    if not (Path(python) / "Python.h").is_file():
        raise SystemExit(f"no Python.h in {python}: install the Python headers (Debian: python3-dev)")
    return python, numpy.get_include()


def rewrite(text: str, python_include: str, numpy_include: str) -> str:
    """The CMake text with the container's include folders replaced; raises ValueError on any other one."""
    text = CONTAINER_NUMPY.sub(numpy_include, CONTAINER_PYTHON.sub(python_include, text))
    unknown = sorted(set(CONTAINER_ANY.findall(text)))
    if unknown:
        raise ValueError(f"paths of the wheels' build container not known here: {', '.join(unknown)}")
    return text


def patch_prefix(prefix: Path) -> list[Path]:
    """Rewrite every CMake file under PREFIX/share that names the container; returns the files changed."""
    python_include, numpy_include = local_includes()
    changed = []
    for path in sorted((prefix / "share").glob("*/cmake/*.cmake")):
        text = path.read_text()
        if "/opt/python/" not in text:
            continue
        try:
            fixed = rewrite(text, python_include, numpy_include)
        except ValueError as exc:
            raise SystemExit(f"{path}: {exc}") from None
        handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
        with os.fdopen(handle, "w") as out:
            out.write(fixed)
        os.chmod(temporary, path.stat().st_mode & 0o777)
        os.replace(temporary, path)
        changed.append(path)
    return changed


def main(argv: list[str]) -> int:
    if len(argv) != 2 or not Path(argv[1], "share").is_dir():
        print(__doc__.strip().splitlines()[-1].strip(), file=sys.stderr)
        return 2
    changed = patch_prefix(Path(argv[1]))
    print(f"wheel CMake files pointed at this machine's Python and NumPy headers: {len(changed)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
