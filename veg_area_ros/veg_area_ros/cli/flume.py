"""`veg-area vogel`: the Vogel exponent (Cd·Af ∝ U^psi) of a plant from an experiment table or from bags of
flume runs (force, velocity and Af recorded together), with its confidence interval and a log-log plot."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from .common import EXIT_USAGE, CliError, check_outputs, check_writable, positive_float, probability

WATER_DENSITY = 998.2  # kg/m³ at 20 °C: drag.WATER_DENSITY, not imported here (the parser loads no numpy)
BAG_OPTIONS = {"force_axis": "+x", "velocity_axis": "+x", "force_topic": "/force", "velocity_topic": "/velocity",
               "area_topic": "/projected_area"}  # what reading a bag takes, with its default


def add_parser(sub: argparse._SubParsersAction) -> None:
    vog = sub.add_parser("vogel", help="fit the Vogel exponent (Cd·Af ∝ U^psi) to an experiment table, with "
                         "its confidence interval and a log-log plot")
    vog.add_argument("inputs", nargs="+", metavar="TABLE_OR_BAGS",
                     help="a CSV with velocity_m_s, force_n, area_m2 (optional density) per run, or rosbag2 (or "
                          "ROS 1) bags recorded with force, velocity and projected_area, one run each")
    vog.add_argument("--force-axis", default=BAG_OPTIONS["force_axis"],
                     help="bags: force component along the flow, +x .. -z (a minus sign: --force-axis=-y; "
                          "default %(default)s)")
    vog.add_argument("--velocity-axis", default=BAG_OPTIONS["velocity_axis"],
                     help="bags: velocity component along the flow (default %(default)s)")
    vog.add_argument("--force-topic", default=BAG_OPTIONS["force_topic"],
                     help="bags: geometry_msgs/WrenchStamped topic (default %(default)s)")
    vog.add_argument("--velocity-topic", default=BAG_OPTIONS["velocity_topic"],
                     help="bags: geometry_msgs/TwistStamped topic (default %(default)s)")
    vog.add_argument("--area-topic", default=BAG_OPTIONS["area_topic"],
                     help="bags: Af topic (veg_area_msgs/ProjectedArea, or the Vector3Stamped of earlier "
                          "recordings: x = Af, y = its std; default %(default)s)")
    vog.add_argument("--density", type=positive_float, default=None,
                     help=f"water density, kg/m³, where a table row gives none (default {WATER_DENSITY}: 20 °C)")
    vog.add_argument("--confidence", type=probability, default=0.95,
                     help="of the exponent's interval (default %(default)s)")
    vog.add_argument("--plot", help="PNG (default: the first input's name + .vogel.png)")
    vog.add_argument("--json", action="store_true")
    vog.set_defaults(func=cmd_vogel)



def cmd_vogel(args: argparse.Namespace) -> int:
    from ..bags import BagError, bag_run
    from ..drag import DragError, format_run_table, plot_vogel, read_table, run_table, unit_slips, vogel_fit
    from ..frames import is_bag

    density = WATER_DENSITY if args.density is None else args.density
    bags = [Path(i) for i in args.inputs if is_bag(Path(i))]
    if (bags and len(bags) != len(args.inputs)) or (not bags and len(args.inputs) != 1):
        raise CliError("give one experiment table (CSV), or rosbag2 bags (one run each)", EXIT_USAGE)
    given = [f"--{name.replace('_', '-')}" for name, default in BAG_OPTIONS.items() if getattr(args, name) != default]
    if given and not bags:  # they were ignored without a word
        raise CliError(f"{', '.join(given)} {'reads' if len(given) == 1 else 'read'} bags of recorded runs; a table's "
                       "rows give U, F and Af themselves", EXIT_USAGE)
    plot = Path(args.plot) if args.plot else Path(args.inputs[0].rstrip("/")).with_suffix(".vogel.png")
    check_outputs([("--plot", str(plot), True)], args.inputs, "fitted")
    if args.plot is not None and Path(args.plot).suffix.lower() != ".png":  # it is drawn as PNG whatever the name
        raise CliError(f"--plot {args.plot}: the plot is a PNG image; give a name ending in .png", EXIT_USAGE)
    check_writable([("--plot", plot, False)], "fitted")
    try:
        if bags:
            runs = [bag_run(b, args.force_axis, args.velocity_axis, args.force_topic, args.velocity_topic,
                            args.area_topic) for b in bags]
            for run in runs:
                print(f"{run['run']}: U = {run['velocity_m_s']:.4g} m/s, F = {run['force_n']:.4g} N, "
                      f"Af = {run['area_m2']:.4g} m² ({run['samples']['force']} force, "
                      f"{run['samples']['velocity']} velocity, {run['samples']['area']} Af samples)",
                      file=sys.stderr)
            table = run_table(runs, density, "bags")
        else:
            rows = read_table(args.inputs[0])
            if args.density is not None and rows and all(str(r.get("density") or "").strip() for r in rows):
                raise CliError(f"--density {args.density:g} is the water's where a row gives none, and every row of "
                               f"{args.inputs[0]} gives its density", EXIT_USAGE)
            table = run_table(rows, density, args.inputs[0])
        slips = unit_slips(table)
        if slips:  # Cd of 0.001 or 10000 fitted and plotted with exit 0 before
            raise DragError("the runs' units look wrong, nothing was fitted (columns are velocity_m_s in m/s, "
                            "force_n in N, area_m2 in m²): " + "; ".join(slips))
        velocity = [r["velocity_m_s"] for r in table]
        cd_area = [r["cd_area_m2"] for r in table]
        fit = vogel_fit(velocity, cd_area, args.confidence)
    except (DragError, BagError) as exc:
        raise CliError(str(exc)) from exc
    plot.parent.mkdir(parents=True, exist_ok=True)
    plot_vogel(velocity, cd_area, fit, plot, [r["cd_area_std_m2"] for r in table])
    r_squared = fit.r_squared if math.isfinite(fit.r_squared) else None  # JSON has no NaN
    result = {"exponent": fit.exponent, "interval": list(fit.interval), "confidence": fit.confidence,
              "coefficient_m2": fit.coefficient, "r_squared": r_squared, "runs": fit.runs, "plot": str(plot),
              "density_kg_m3": density, "per_run": table}
    if args.json:
        print(json.dumps(result, allow_nan=False))
    else:
        low, high = fit.interval
        print(format_run_table(table))
        fitted = f"R² {r_squared:.4f}" if r_squared is not None else "R² undefined: Cd·Af is the same in every run"
        print(f"Vogel exponent psi = {fit.exponent:.4f}, {fit.confidence:.0%} interval [{low:.4f}, {high:.4f}] "
              f"({fit.runs} runs, {fitted}); Cd·Af = {fit.coefficient:.4g} m² x U^psi")
        print(f"plot: {plot}")
    return 0
