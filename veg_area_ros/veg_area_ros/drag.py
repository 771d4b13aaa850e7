"""Drag coefficients from Af, a force and a velocity, and the Vogel exponent of a plant's reconfiguration.

No ROS here. Cd = 2 F / (rho U^2 Af), its uncertainty propagated to first order. Streams are aligned on the
Af frame's timestamp: force and velocity are averaged over +-tolerance around it (force balances sample
far faster than cameras, and their mean is what the frame saw). Vogel: Cd Af ∝ U^psi, fitted in log-log with
a Student-t confidence interval (psi = 0 for a rigid bluff body, about -1 for a very flexible plant).
"""

from __future__ import annotations

import bisect
import csv
import io
import math
import re
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from .files import save_figure, special_file

WATER_DENSITY = 998.2  # kg/m³ at 20 °C
AXES = ("+x", "-x", "+y", "-y", "+z", "-z")  # signed: a sensor may point against the flow; and a bare
# "y" would be read as a boolean by the ROS parameter YAML parser


def check_axis(axis: str) -> str:
    """The axis if it is one of AXES; DragError with the choices otherwise."""
    if axis not in AXES:
        raise DragError(f"axes must be one of {', '.join(AXES)}, got {axis!r}")
    return axis


def component(vector: object, axis: str) -> float:
    """The signed component ("+x" .. "-z") of anything with x, y, z attributes (geometry_msgs/Vector3)."""
    check_axis(axis)
    return (1.0 if axis[0] == "+" else -1.0) * getattr(vector, axis[1])


class DragError(ValueError):
    """Inputs that cannot give a drag coefficient or a fit; the message says why."""


@dataclass(frozen=True)
class Drag:
    time_s: float
    cd: float
    cd_std: float
    force_n: float
    velocity_m_s: float
    area_m2: float
    force_samples: int
    velocity_samples: int
    area_std_m2: float = 0.0


def drag_coefficient(force: float, velocity: float, area: float, density: float = WATER_DENSITY,
                     force_std: float = 0.0, velocity_std: float = 0.0, area_std: float = 0.0,
                     density_std: float = 0.0) -> tuple[float, float]:
    """(Cd, its standard deviation) from F (N), U (m/s), Af (m²) and rho (kg/m³)."""
    values = np.array([force, velocity, area, density], float)
    if not np.all(np.isfinite(values)) or velocity == 0 or area <= 0 or density <= 0:
        raise DragError(f"no drag coefficient from F={force}, U={velocity}, Af={area}, rho={density}")
    cd = 2 * force / (density * velocity**2 * area)
    relative = math.hypot(force_std / force if force else 0.0, 2 * velocity_std / velocity,
                          area_std / area, density_std / density)
    return cd, abs(cd) * relative


class _Stream:
    """Recent (time, value) samples of one instrument, in time order."""

    def __init__(self, horizon_s: float):
        self.times: deque[float] = deque()
        self.values: deque[float] = deque()
        self.horizon_s = horizon_s
        self.rejected = 0  # non-finite samples (an instrument's glitch): one would spoil every window it is in

    def add(self, t: float, value: float) -> None:
        if not (math.isfinite(t) and math.isfinite(value)):
            self.rejected += 1
            return
        if self.times and t < self.times[-1]:
            return  # out of order (a replayed bag restarting): ignored rather than breaking the order
        self.times.append(t)
        self.values.append(value)
        while self.times and self.times[0] < t - self.horizon_s:
            self.times.popleft()
            self.values.popleft()

    def window(self, t: float, tolerance: float) -> np.ndarray:
        times = list(self.times)
        lo, hi = bisect.bisect_left(times, t - tolerance), bisect.bisect_right(times, t + tolerance)
        return np.array(list(self.values)[lo:hi], float)

    def covers(self, t: float) -> bool:
        return bool(self.times) and self.times[-1] >= t


class DragAligner:
    """Feed force, velocity and Af samples as they come (any order between streams); `ready()` returns the
    drag coefficients of the Af samples whose ±tolerance window is complete in both other streams.
    Af samples with no force or velocity in their window are counted in `unmatched`."""

    def __init__(self, tolerance_s: float = 0.05, density: float = WATER_DENSITY, force_std: float = 0.0,
                 velocity_std: float = 0.0, give_up_s: float = 2.0):
        if tolerance_s <= 0 or density <= 0:
            raise DragError("tolerance and density must be positive")
        self.tolerance_s, self.density = tolerance_s, density
        self.force_std, self.velocity_std = force_std, velocity_std  # instrument noise of one sample
        self.give_up_s = give_up_s
        horizon = 4 * (tolerance_s + give_up_s)
        self.force, self.velocity = _Stream(horizon), _Stream(horizon)
        self.pending: deque[tuple[float, float, float]] = deque()
        self.unmatched = 0

    def add_force(self, t: float, newtons: float) -> None:
        self.force.add(t, newtons)

    def add_velocity(self, t: float, metres_per_second: float) -> None:
        self.velocity.add(t, metres_per_second)

    @property
    def rejected_samples(self) -> int:
        """Force and velocity samples left out for being NaN or infinite."""
        return self.force.rejected + self.velocity.rejected

    def add_area(self, t: float, area_m2: float, area_std_m2: float = 0.0) -> None:
        self.pending.append((t, area_m2, area_std_m2))

    def _mean(self, samples: np.ndarray, instrument_std: float) -> tuple[float, float]:
        spread = samples.std(ddof=1) if len(samples) > 1 else 0.0
        return float(samples.mean()), float(max(spread, instrument_std) / math.sqrt(len(samples)))

    def ready(self) -> list[Drag]:
        done = []
        while self.pending:
            t, area, area_std = self.pending[0]
            end = t + self.tolerance_s
            latest = max(self.force.times[-1] if self.force.times else -math.inf,
                         self.velocity.times[-1] if self.velocity.times else -math.inf)
            if not (self.force.covers(end) and self.velocity.covers(end)) and latest < end + self.give_up_s:
                break  # the window may still fill
            self.pending.popleft()
            forces, velocities = self.force.window(t, self.tolerance_s), self.velocity.window(t, self.tolerance_s)
            if len(forces) == 0 or len(velocities) == 0:
                self.unmatched += 1
                continue
            force, force_std = self._mean(forces, self.force_std)
            velocity, velocity_std = self._mean(velocities, self.velocity_std)
            try:
                cd, cd_std = drag_coefficient(force, velocity, area, self.density, force_std, velocity_std, area_std)
            except DragError:
                self.unmatched += 1
                continue
            done.append(Drag(t, cd, cd_std, force, velocity, area, len(forces), len(velocities), area_std))
        return done


@dataclass(frozen=True)
class VogelFit:
    exponent: float  # psi in Cd Af ∝ U^psi
    interval: tuple[float, float]  # confidence interval of psi
    confidence: float
    coefficient: float  # Cd Af at U = 1 m/s
    r_squared: float
    runs: int


def vogel_fit(velocity: ArrayLike, cd_area: ArrayLike, confidence: float = 0.95) -> VogelFit:
    """Least squares of log(Cd Af) = log(k) + psi log(U) over runs; Student-t interval on psi."""
    u, y = np.asarray(velocity, float), np.asarray(cd_area, float)
    if u.shape != y.shape or len(u) < 3:
        raise DragError(f"the Vogel fit needs at least 3 runs, got {len(u)}")
    if np.any(u <= 0) or np.any(y <= 0) or not np.all(np.isfinite(u) & np.isfinite(y)):
        raise DragError("velocities and Cd·Af must be positive and finite for a log-log fit")
    x, z = np.log(u), np.log(y)
    if np.ptp(x) == 0:
        raise DragError("all runs have the same velocity: no exponent can be fitted")
    # by hand, not scipy's linregress: runs that lie exactly on a line (a table made up to try the command)
    # gave a NaN interval and R², and NaN in the --json output, which is no JSON
    dx, dz = x - x.mean(), z - z.mean()
    slope = float(dx @ dz / (dx @ dx))
    residual = float(np.sum((dz - slope * dx) ** 2))
    stderr = math.sqrt(residual / (len(u) - 2) / (dx @ dx))
    half = float(stats.t.ppf(0.5 + confidence / 2, len(u) - 2)) * stderr
    spread = float(dz @ dz)
    # R² is undefined where Cd·Af is the same in every run (to its last digits): NaN, said so by the command
    flat = spread <= (1e-12 * max(1.0, float(np.abs(z).max()))) ** 2 * len(z)
    r_squared = math.nan if flat else 1 - residual / spread
    return VogelFit(slope, (slope - half, slope + half), confidence, float(np.exp(z.mean() - slope * x.mean())),
                    r_squared, len(u))


def read_runs(path: str | Path, density: float = WATER_DENSITY) -> tuple[np.ndarray, np.ndarray]:
    """Experiment table (CSV with columns velocity_m_s, force_n, area_m2; one row per run) -> (U, Cd·Af)."""
    return runs_to_vogel(read_table(path), density, str(path))


def read_table(path: str | Path) -> list[dict]:
    """An experiment table's rows (CSV with columns velocity_m_s, force_n, area_m2; optional run, density and
    the std columns of `run_table`), checked for its columns."""
    path = Path(path)
    special = special_file(path)
    if special:
        raise DragError(f"{path}: {special}")
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            text = handle.read()
    except OSError as exc:
        raise DragError(f"{path}: cannot read ({exc.strerror})") from exc
    except UnicodeDecodeError as exc:  # a spreadsheet's "CSV" in a legacy code page
        raise DragError(f"{path}: not UTF-8 text (byte {exc.start}); save it as 'CSV UTF-8'") from exc
    try:
        rows = _table_rows(text)
    except DragError as exc:
        raise DragError(f"{path}: {exc}") from exc
    needed = {"velocity_m_s", "force_n", "area_m2"}
    if not rows or not needed <= set(rows[0]):
        has = f"it has {', '.join(repr(c) for c in rows[0] if c is not None)}" if rows else "it has no data row"
        raise DragError(f"{path}: needs columns {', '.join(sorted(needed))}; {has}")
    return rows


DECIMAL_COMMA = re.compile(r"[-+]?\d*,\d+([eE][-+]?\d+)?")


def _table_rows(text: str) -> list[dict]:
    """A table's rows as comma-separated, or as a spreadsheet in a decimal-comma locale saves it: separated by
    ';' (or tabs), with numbers such as 0,25."""
    header = text.splitlines()[0] if text.strip() else ""
    delimiter = max((",", ";", "\t"), key=header.count)
    reader = csv.DictReader(io.StringIO(text, newline=""), delimiter=delimiter)
    named = [name.strip() for name in reader.fieldnames or [] if name.strip()]
    twice = sorted({name for name in named if named.count(name) > 1})
    if twice:  # a reader keeps the last of two equal columns without a word (a pasted column read as the force)
        raise DragError(f"the column{'s' if len(twice) > 1 else ''} {', '.join(map(repr, twice))} "
                        f"appear{'' if len(twice) > 1 else 's'} twice in the header; keep one")
    rows = list(reader)
    if delimiter != ",":
        rows = [{key: (value.replace(",", ".") if isinstance(value, str) and DECIMAL_COMMA.fullmatch(value.strip())
                       else value) for key, value in row.items()} for row in rows]
    return rows


def runs_to_vogel(rows: list[dict], density: float = WATER_DENSITY, source: str = "runs") -> tuple[np.ndarray,
                                                                                                      np.ndarray]:
    """Runs (velocity_m_s, force_n, area_m2 and optionally density each) -> (U, Cd·Af)."""
    table = run_table(rows, density, source)
    return np.array([r["velocity_m_s"] for r in table]), np.array([r["cd_area_m2"] for r in table])


def run_table(rows: list[dict], density: float = WATER_DENSITY, source: str = "runs") -> list[dict]:
    """Each run's U, F, Af, Cd and Cd·Af with their standard deviations (the optional columns velocity_std_m_s,
    force_std_n, area_std_m2; zero where absent). Cd·Af = 2F / (rho U²) needs no Af: its std comes from F and U
    alone; Cd's adds Af's."""
    table = []
    for line, row in enumerate(rows, 2):
        try:
            empty = [key for key in ("velocity_m_s", "force_n", "area_m2")
                     if row.get(key) is None or str(row[key]).strip() == ""]
            if empty:
                raise DragError(f"no {' and no '.join(empty)} (an empty cell): fill it in or delete the run")
            values = {key: float(row.get(key) or 0.0) for key in ("velocity_m_s", "force_n", "area_m2",
                                                                 "velocity_std_m_s", "force_std_n", "area_std_m2")}
            rho = float(row.get("density") or density)
            cd, cd_std = drag_coefficient(values["force_n"], values["velocity_m_s"], values["area_m2"], rho,
                                          values["force_std_n"], values["velocity_std_m_s"], values["area_std_m2"])
            _, cd_area_relative = drag_coefficient(values["force_n"], values["velocity_m_s"], values["area_m2"], rho,
                                                   values["force_std_n"], values["velocity_std_m_s"])
        except (ValueError, DragError) as exc:
            raise DragError(f"{source}, line {line}: {exc}") from exc
        table.append({"run": str(row.get("run") or line - 1), **values, "density": rho, "cd": cd, "cd_std": cd_std,
                      "cd_area_m2": cd * values["area_m2"],
                      "cd_area_std_m2": cd_area_relative * values["area_m2"]})
    return table


# what a plant in a flume or a river can show; far outside, a column is in another unit (cm/s, cm², mN, grams)
MAX_VELOCITY_M_S = 15.0  # rivers in spate reach 5-7 m/s
MAX_AREA_M2 = 25.0  # a tree in a flood; a flume's plants are cm² to dm²
CD_RANGE = (0.005, 50.0)  # streamlined, reconfigured shoots near 0.05; a stem at Reynolds number 10 about 3


def unit_slips(table: list[dict]) -> list[str]:
    """What in the runs looks like a column in another unit, once per kind with its runs and range, or nothing:
    a velocity above MAX_VELOCITY_M_S, an area above MAX_AREA_M2, else a Cd outside CD_RANGE."""
    low, high = CD_RANGE
    kinds = {  # label: (column, unit, why, whether a run's value is wrong)
        "U": ("velocity_m_s", " m/s", "beyond any flume or river (velocity_m_s in cm/s?)",
              lambda r: abs(r["velocity_m_s"]) > MAX_VELOCITY_M_S),
        "Af": ("area_m2", " m²", "beyond any plant measured here (area_m2 in cm²?)",
               lambda r: r["area_m2"] > MAX_AREA_M2),
        "Cd": ("cd", "", f"outside {low:g}-{high:g}, what plants show (force_n in mN or grams, velocity_m_s in "
               "cm/s or area_m2 in cm²?)", lambda r: not low <= abs(r["cd"]) <= high),
    }
    found, explained = [], set()
    for label, (key, unit, why, wrong) in kinds.items():
        runs = [r for r in table if wrong(r) and (label != "Cd" or r["run"] not in explained)]
        if runs:
            values = [r[key] for r in runs]
            span = f"{min(values):.3g}" + (f" to {max(values):.3g}" if len(runs) > 1 else "")
            found.append(f"{label} = {span}{unit} in run{'s' if len(runs) > 1 else ''} "
                         f"{', '.join(r['run'] for r in runs)} is {why}")
            explained.update(r["run"] for r in runs)
    return found


def format_run_table(table: list[dict]) -> str:
    """The runs as a text table (U, F, Af, Cd with their std)."""
    lines = [f"{'run':>12} {'U [m/s]':>16} {'F [N]':>18} {'Af [m²]':>22} {'Cd':>16}"]
    for r in table:
        lines.append(f"{Path(r['run']).name[-12:]:>12} {r['velocity_m_s']:8.4g} ± {r['velocity_std_m_s']:<5.2g} "
                     f"{r['force_n']:9.4g} ± {r['force_std_n']:<6.2g} {r['area_m2']:11.4g} ± {r['area_std_m2']:<8.2g} "
                     f"{r['cd']:7.4g} ± {r['cd_std']:<6.2g}")
    return "\n".join(lines)


def _tick_digits(low: float, high: float) -> tuple[float, ...] | None:
    """The leading digits of a log axis's labelled ticks: 1, 2 and 5 where at least two fall in [low, high], else
    every digit; None where even those are fewer than two (a span narrower than one digit's step)."""
    decades = 10.0 ** np.arange(np.floor(np.log10(low)), np.ceil(np.log10(high)) + 1)
    for digits in ((1.0, 2.0, 5.0), tuple(float(d) for d in range(1, 10))):
        ticks = np.outer(decades, digits).ravel()
        if np.count_nonzero((ticks >= low) & (ticks <= high)) >= 2:
            return digits
    return None


def plot_vogel(velocity: ArrayLike, cd_area: ArrayLike, fit: VogelFit, path: str | Path,
               cd_area_std: ArrayLike | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    figure, axes = plt.subplots(figsize=(5, 4))
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.errorbar(velocity, cd_area, yerr=cd_area_std, fmt="o", capsize=3, label="runs (±1 std)")
    u = np.geomspace(np.min(velocity), np.max(velocity), 50)
    low, high = fit.interval
    axes.loglog(u, fit.coefficient * u**fit.exponent, "-",
                label=f"ψ = {fit.exponent:.3f} [{low:.3f}, {high:.3f}] ({fit.confidence:.0%})")
    # plain numbers at 1, 2, 5 (every digit where the span holds fewer than two of those): log labels as
    # 3x10^-1 ran into each other
    for axis, limits in ((axes.xaxis, axes.get_xlim()), (axes.yaxis, axes.get_ylim())):
        digits = _tick_digits(*limits)
        if digits is None:
            continue
        axis.set_major_locator(LogLocator(base=10, subs=digits))
        axis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        axis.set_minor_formatter(NullFormatter())
    axes.set_xlabel("U (m/s)")
    axes.set_ylabel("Cd·Af (m²)")
    axes.legend()
    axes.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    save_figure(figure, path, dpi=120)
    plt.close(figure)
