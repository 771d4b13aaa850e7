"""Which DDS transport the nodes use: one rule for every entry point (nodes, `veg-area` commands, launch).
No ROS here.

VEG_AREA_TRANSPORT picks it:
- `auto` (default): config/fastdds.xml, shared memory on this machine and UDPv4 on every interface with
  32 MB socket buffers, so camera-sized images reach other machines too (raise net.core.rmem_max and
  wmem_max to 33554432 on each PC; `buffer_warning` says when they are lower);
- `local`: config/fastdds_local.xml, shared memory plus UDP on 127.0.0.1: nothing leaves this machine;
- `default`: Fast DDS's own defaults (512 KB shared-memory segments: camera-sized best-effort images are
  mostly lost).
A profile the user set (FASTDDS_DEFAULT_PROFILES_FILE) or another RMW_IMPLEMENTATION is left alone.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

PROFILES = {"auto": "fastdds.xml", "local": "fastdds_local.xml", "default": None}
SOCKET_BUFFER_BYTES = 33554432  # what config/fastdds.xml asks the kernel for
INDEX_MARKER = Path("share", "ament_index", "resource_index", "packages", "veg_area_ros")


@dataclass(frozen=True)
class Transport:
    name: str  # auto | local | default | user profile | another rmw
    profile: str | None  # the Fast DDS XML profile to load, if we set one
    description: str  # one line for the start-up log

    def apply(self, environ: dict) -> None:
        """Set the profile in `environ` (before rclpy.init) when this transport has one of ours."""
        if self.name in ("auto", "local") and self.profile:
            environ["FASTDDS_DEFAULT_PROFILES_FILE"] = self.profile


def ament_prefix(environ: dict) -> Path | None:
    """The first AMENT_PREFIX_PATH prefix that holds this package: the ament index's rule (its marker under
    share/ament_index/resource_index/packages), read without importing ament_index_python, which raises when
    no ament environment is set; None when none does."""
    prefixes = (Path(p) for p in environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p)
    return next((p for p in prefixes if (p / INDEX_MARKER).is_file()), None)


def config_locations(name: str, environ: dict | None = None) -> list[tuple[Path, str]]:
    """Where a file of the package's config/ may be, best first, each with how it was found: the ament index
    (a sourced ROS 2 or colcon install), beside the running interpreter's prefix (an unsourced `.venv`, where
    colcon installed into the venv itself), then the source tree. No ament environment is a normal state, not
    an error: the index is then skipped."""
    found: list[tuple[Path, str]] = []
    prefix = ament_prefix(os.environ if environ is None else environ)
    if prefix is not None:
        found.append((prefix / "share" / "veg_area_ros" / "config" / name, "ament index"))
    found.append((Path(sys.prefix) / "share" / "veg_area_ros" / "config" / name, "this interpreter's prefix"))
    found.append((Path(__file__).resolve().parents[1] / "config" / name, "the source tree"))
    return found


def find_config(name: str, environ: dict | None = None) -> tuple[str, str] | None:
    """The first existing file of `config_locations` and how it was found, or None."""
    return next(((str(path), how) for path, how in config_locations(name, environ) if path.is_file()), None)


def config_file(name: str, environ: dict | None = None) -> str | None:
    """A file of the package's config/ (see `config_locations`), or None."""
    found = find_config(name, environ)
    return found[0] if found else None


def choose_transport(environ: dict) -> Transport:
    """The transport for a process with this environment (see the module's docstring)."""
    if "FASTDDS_DEFAULT_PROFILES_FILE" in environ:
        path = environ["FASTDDS_DEFAULT_PROFILES_FILE"]
        ours = next((name for name, file in PROFILES.items() if file and Path(path).name == file), None)
        return Transport(ours or "user profile", path, f"Fast DDS profile {path}"
                         + (f" (veg_area_ros '{ours}')" if ours else " (FASTDDS_DEFAULT_PROFILES_FILE)"))
    rmw = environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    if rmw != "rmw_fastrtps_cpp":
        return Transport("another rmw", None, f"{rmw} with its own settings (VEG_AREA_TRANSPORT applies to Fast DDS)")
    wanted = environ.get("VEG_AREA_TRANSPORT", "auto") or "auto"
    if wanted not in PROFILES:
        raise ValueError(f"VEG_AREA_TRANSPORT must be one of {', '.join(PROFILES)}, got {wanted!r}")
    if wanted == "default":
        return Transport("default", None, "Fast DDS defaults (VEG_AREA_TRANSPORT=default): camera-sized "
                         "best-effort images are mostly lost")
    found = find_config(PROFILES[wanted], environ)
    if found is None:
        looked = ", ".join(str(path) for path, _ in config_locations(PROFILES[wanted], environ))
        return Transport("default", None, f"Fast DDS defaults: config/{PROFILES[wanted]} not found (looked in "
                         f"{looked}): camera-sized best-effort images are mostly lost")
    profile, how = found
    reach = "this machine and others over UDP" if wanted == "auto" else "this machine only"
    return Transport(wanted, profile, f"veg_area_ros '{wanted}' ({reach}): {profile} (found via {how})")


def low_socket_buffers(proc: Path = Path("/proc/sys/net/core")) -> dict[str, int]:
    """net.core's rmem_max and wmem_max where they are below what the profile asks for (unreadable: left out)."""
    low = {}
    for key in ("rmem_max", "wmem_max"):
        try:
            value = int((proc / key).read_text())
        except (OSError, ValueError):
            continue
        if value < SOCKET_BUFFER_BYTES:
            low[key] = value
    return low


def buffer_warning(transport: Transport, proc: Path = Path("/proc/sys/net/core")) -> str | None:
    """Why images to other machines may be lost with this transport (socket buffers capped below what the
    profile asks for), or None."""
    low = low_socket_buffers(proc) if transport.name == "auto" else {}
    if not low:
        return None
    now = ", ".join(f"{k} {v}" for k, v in low.items())
    return (f"net.core {now} caps the UDP socket buffers below {SOCKET_BUFFER_BYTES}: camera-sized images to "
            f"other machines may be lost; once per PC: sudo sysctl -w net.core.rmem_max={SOCKET_BUFFER_BYTES} "
            f"net.core.wmem_max={SOCKET_BUFFER_BYTES}")
