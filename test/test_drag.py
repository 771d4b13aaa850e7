"""Drag coefficients and the Vogel exponent: known Cd from noisy, unsynchronised streams;
a known exponent inside its reported interval; the `veg-area vogel` command."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import run_cli
from scipy import stats

from veg_area_ros.drag import WATER_DENSITY, DragAligner, DragError, drag_coefficient, vogel_fit


def test_drag_coefficient_and_its_uncertainty():
    cd, std = drag_coefficient(0.5 * WATER_DENSITY * 0.04 * 0.01 * 1.2, 0.2, 0.01, force_std=0.0, velocity_std=0.002)
    assert cd == pytest.approx(1.2, rel=1e-12)
    assert std == pytest.approx(1.2 * 2 * 0.01, rel=1e-9)  # 1 % on U is 2 % on Cd
    with pytest.raises(DragError):
        drag_coefficient(1.0, 0.0, 0.01)


def test_aligned_streams_give_the_known_cd_within_half_a_percent():
    rng = np.random.default_rng(11)
    true_cd, area, aligner = 0.9, 0.0105, DragAligner(tolerance_s=0.05, force_std=0.0)
    results = []
    for k in range(2000):  # 1 kHz force, 25 Hz velocity with its own clock offset, 10 Hz Af
        t = k * 0.001
        velocity = 0.25 + 0.05 * np.sin(t)  # a slowly changing flow
        force = 0.5 * WATER_DENSITY * velocity**2 * area * true_cd
        aligner.add_force(t, force * (1 + 0.015 * rng.standard_normal()))  # balance noise
        if k % 40 == 7:
            aligner.add_velocity(t, velocity)
        if k % 100 == 50:
            aligner.add_area(t, area, 0.001 * area)
        results += aligner.ready()
    assert len(results) >= 18 and aligner.unmatched == 0
    cds = np.array([r.cd for r in results])
    assert np.all(np.abs(cds / true_cd - 1) <= 0.005), cds
    assert all(abs(r.cd - true_cd) <= 3 * r.cd_std for r in results)  # the stated uncertainty covers it
    assert all(r.force_samples >= 100 and r.velocity_samples >= 2 for r in results)


def test_glitched_instrument_samples_are_left_out_and_counted():
    """A NaN or infinite sample (a balance or probe glitch) would make every window holding it give no Cd."""
    area, aligner = 0.01, DragAligner(tolerance_s=0.05)
    force = 0.5 * WATER_DENSITY * 0.3**2 * area * 1.1
    results = []
    for k in range(1000):
        t = k * 0.001
        aligner.add_force(t, float("nan") if k % 50 == 3 else force)
        if k % 40 == 7:
            aligner.add_velocity(t, float("inf") if k == 407 else 0.3)
        if k % 100 == 50:
            aligner.add_area(t, area)
        results += aligner.ready()
    assert aligner.rejected_samples == 20 + 1 and aligner.unmatched == 0
    assert len(results) >= 8 and all(r.cd == pytest.approx(1.1, rel=1e-12) for r in results)


def test_an_area_without_force_in_its_window_is_counted_not_guessed():
    aligner = DragAligner(tolerance_s=0.01, give_up_s=0.5)
    aligner.add_area(1.0, 0.01)
    for k in range(100):
        aligner.add_force(2.0 + k * 0.01, 1.0)
        aligner.add_velocity(2.0 + k * 0.01, 0.3)
    assert aligner.ready() == [] and aligner.unmatched == 1


def test_vogel_fit_recovers_a_known_exponent_within_its_interval():
    rng = np.random.default_rng(3)
    inside = 0
    for _ in range(40):
        velocity = np.linspace(0.1, 0.6, 8)
        cd_area = 0.012 * velocity ** -0.7 * np.exp(0.03 * rng.standard_normal(8))
        fit = vogel_fit(velocity, cd_area)
        inside += fit.interval[0] <= -0.7 <= fit.interval[1]
    assert inside >= 34  # a 95 % interval: about 38 of 40
    exact = vogel_fit([0.1, 0.2, 0.4], [1.0, 0.5, 0.25])
    assert exact.exponent == pytest.approx(-1.0) and exact.r_squared == pytest.approx(1.0)
    with pytest.raises(DragError, match="at least 3 runs"):
        vogel_fit([0.1, 0.2], [1, 2])


def test_vogel_command_on_an_experiment_table(tmp_path):
    velocity = np.array([0.1, 0.15, 0.2, 0.3, 0.4, 0.5])
    area = 0.02 * velocity ** -0.3  # the plant streamlines: Af shrinks with U
    cd = 1.1 * velocity ** -0.2
    force = 0.5 * WATER_DENSITY * velocity**2 * area * cd
    table = tmp_path / "runs.csv"
    table.write_text("velocity_m_s,force_n,area_m2\n" + "".join(f"{u},{f},{a}\n" for u, f, a in
                                                                 zip(velocity, force, area, strict=True)))
    done = run_cli("vogel", str(table), "--json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["exponent"] == pytest.approx(-0.5, abs=1e-9) and result["runs"] == 6
    assert (tmp_path / "runs.vogel.png").stat().st_size > 1000
    # each run's Cd and its std (from the optional std columns): in the text and --json; defaults in --help
    table.write_text("velocity_m_s,force_n,area_m2,force_std_n,velocity_std_m_s,area_std_m2\n" + "".join(
        f"{u},{f},{a},{0.02 * f},{0.01 * u},{0.03 * a}\n" for u, f, a in zip(velocity, force, area, strict=True)))
    done = run_cli("vogel", str(table), "--json")
    runs = json.loads(done.stdout)["per_run"]
    assert [r["cd"] for r in runs] == pytest.approx(cd, rel=1e-9)
    # Cd = 2F / (rho U² Af): relative std hypot(2 %, 2 x 1 %, 3 %); Cd·Af's without Af's
    expected = float(np.sqrt(0.02**2 + 0.02**2 + 0.03**2))
    assert [r["cd_std"] / r["cd"] for r in runs] == pytest.approx([expected] * 6, rel=1e-9)
    assert [r["cd_area_std_m2"] / r["cd_area_m2"] for r in runs] == pytest.approx([np.hypot(0.02, 0.02)] * 6)
    text = run_cli("vogel", str(table)).stdout
    assert text.splitlines()[0].split() == ["run", "U", "[m/s]", "F", "[N]", "Af", "[m²]", "Cd"]
    assert f"{cd[0]:7.4g} ± " in text
    assert "(default 998.2: 20 °C)" in " ".join(run_cli("vogel", "--help").stdout.split())
    table.write_text("velocity_m_s,force_n\n0.1,1\n")
    bad = run_cli("vogel", str(table))
    assert bad.returncode == 1 and "needs columns" in bad.stderr


def test_runs_exactly_on_the_line_give_a_zero_width_interval_and_json_that_parses(tmp_path):
    """A made-up table whose runs lie exactly on F ∝ U² (Cd·Af the same in every run): the interval and R² were
    NaN, and the --json output held NaN, which strict JSON readers (JavaScript, jq) refuse. The interval is
    now the exponent itself, R² is null in JSON and said to be undefined in the text; a column named twice in
    the header (the reader kept the last one, and the runs were blamed on their units) is refused."""
    scattered = vogel_fit([0.1, 0.2, 0.3, 0.4], [1.0, 0.52, 0.33, 0.26])
    reference = stats.linregress(np.log([0.1, 0.2, 0.3, 0.4]), np.log([1.0, 0.52, 0.33, 0.26]))
    assert scattered.exponent == pytest.approx(reference.slope)
    half = stats.t.ppf(0.975, 2) * reference.stderr
    assert scattered.interval == pytest.approx((reference.slope - half, reference.slope + half))
    assert scattered.r_squared == pytest.approx(reference.rvalue**2)
    table = tmp_path / "runs.csv"
    table.write_text("velocity_m_s,force_n,area_m2\n0.1,0.05,0.01\n0.2,0.2,0.01\n0.3,0.45,0.01\n0.4,0.8,0.01\n")
    done = run_cli("vogel", str(table), "--json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout, parse_constant=lambda name: pytest.fail(f"{name} in the JSON output"))
    assert result["exponent"] == pytest.approx(0.0, abs=1e-9) and result["r_squared"] is None
    assert result["interval"] == pytest.approx([0.0, 0.0], abs=1e-9)
    assert "R² undefined: Cd·Af is the same in every run" in run_cli("vogel", str(table)).stdout
    table.write_text("velocity_m_s,force_n,area_m2,force_n\n0.1,0.05,0.01,9\n0.2,0.2,0.01,9\n0.3,0.45,0.01,9\n")
    done = run_cli("vogel", str(table))
    assert done.returncode == 1 and "runs.csv: the column 'force_n' appears twice in the header" in done.stderr


def test_vogel_on_a_table_refuses_what_only_bags_read_and_a_density_no_row_takes(tmp_path):
    """The bags' options (axes, topics) with a table, and --density where every row gives its own, were ignored
    without a word; a density some rows lack is taken for those rows alone."""
    from veg_area_ros.cli.flume import WATER_DENSITY as PARSER_DENSITY

    assert PARSER_DENSITY == WATER_DENSITY  # the parser's default, kept apart so the parser loads no numpy
    table = tmp_path / "runs.csv"
    table.write_text("velocity_m_s,force_n,area_m2,density\n0.1,0.05,0.01,1000\n0.2,0.17,0.009,1000\n"
                     "0.3,0.35,0.0085,1000\n")
    for option in (["--force-axis=-y"], ["--velocity-topic", "/adv/velocity"], ["--area-topic", "/a", "--force-topic",
                                                                                  "/f"]):
        done = run_cli("vogel", str(table), *option)
        assert done.returncode == 2 and "read bags of recorded runs" in done.stderr.replace("reads", "read"), \
            done.stderr
    done = run_cli("vogel", str(table), "--density", "1025")
    assert done.returncode == 2 and "every row of" in done.stderr and "gives its density" in done.stderr
    table.write_text("velocity_m_s,force_n,area_m2,density\n0.1,0.05,0.01,1000\n0.2,0.17,0.009,\n"
                     "0.3,0.35,0.0085,1000\n")
    done = run_cli("vogel", str(table), "--density", "1025", "--json")
    assert done.returncode == 0, done.stderr
    assert [r["density"] for r in json.loads(done.stdout)["per_run"]] == [1000, 1025, 1000]


def test_vogel_command_on_bags_one_run_each(tmp_path):
    """Bags recorded in the flume (force, velocity, Af topics), one per run: the exponent of the runs' means,
    with the balance pointing upstream (-y) and the probe along +x. Af as ProjectedArea in two runs and as the
    Vector3Stamped of earlier recordings in the other two: both are read."""
    from geometry_msgs.msg import TwistStamped, Vector3Stamped, WrenchStamped
    from rclpy.serialization import serialize_message

    from veg_area_msgs.msg import ProjectedArea
    from veg_area_ros.bags import BagRecorder

    rng = np.random.default_rng(2)
    velocities = [0.1, 0.2, 0.3, 0.45]
    bags = []
    for run, velocity in enumerate(velocities):
        area = 0.02 * velocity ** -0.3
        force = 0.5 * WATER_DENSITY * velocity**2 * area * 1.1 * velocity ** -0.2
        bags.append(tmp_path / f"run{run}")
        recorder = BagRecorder(bags[-1])
        typed = run % 2 == 0
        for topic, msgtype in (("/force", "geometry_msgs/msg/WrenchStamped"),
                               ("/velocity", "geometry_msgs/msg/TwistStamped"),
                               ("/projected_area", "veg_area_msgs/msg/ProjectedArea" if typed
                                else "geometry_msgs/msg/Vector3Stamped")):
            recorder.add_topic(topic, msgtype)
        for k in range(200):  # symmetric noise: the means are the true values to ~1e-3
            noise = 1 + 0.01 * (1 if k % 2 else -1)
            wrench = WrenchStamped()
            wrench.wrench.force.y = -force * noise
            wrench.wrench.force.x = rng.normal()  # across the flow: must be ignored
            recorder.write("/force", k * 5_000_000, serialize_message(wrench))
            if k % 4 == 0:
                twist = TwistStamped()
                twist.twist.linear.x = velocity
                recorder.write("/velocity", k * 5_000_000, serialize_message(twist))
            if k % 20 == 0:
                if typed:
                    af = ProjectedArea(area_m2=area, area_std_m2=0.01 * area)
                else:
                    af = Vector3Stamped()
                    af.vector.x, af.vector.y = area, 0.01 * area
                recorder.write("/projected_area", k * 5_000_000, serialize_message(af))
        recorder.close()
    done = run_cli("vogel", *map(str, bags), "--force-axis=-y", "--json", "--plot", str(tmp_path / "v.png"))
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["runs"] == 4 and result["exponent"] == pytest.approx(-0.5, abs=1e-6)
    assert "U = 0.1 m/s" in done.stderr and (tmp_path / "v.png").stat().st_size > 1000
    wrong_axis = run_cli("vogel", *map(str, bags), "--force-axis", "y")
    assert wrong_axis.returncode == 1 and "axes must be one of" in wrong_axis.stderr
    empty = run_cli("vogel", *map(str, bags), "--velocity-topic", "/nothing")
    assert empty.returncode == 1 and "no messages on /nothing" in empty.stderr
    mixed = run_cli("vogel", str(bags[0]), str(tmp_path / "v.png"))
    assert mixed.returncode == 2


@pytest.mark.parametrize("slip, column, scale, said", [
    ("velocity in cm/s", "velocity", 100.0, "U = 20 to 50 m/s in runs 3, 4, 5, 6 is beyond any flume"),
    ("area in cm²", "area", 1e4, "is beyond any plant measured here (area_m2 in cm²?)"),
    ("force in mN", "force", 1e3, "Cd = 1.26e+03 to 1.74e+03 in runs 1, 2, 3, 4, 5, 6 is outside 0.005-50"),
])
def test_a_unit_slip_in_the_runs_is_refused_with_the_likely_unit(tmp_path, slip, column, scale, said):
    """A table in cm/s, cm² or mN fitted a Cd of 0.0001 or 1700 and plotted it with exit 0. Refused, nothing
    fitted or plotted, the column and its likely unit named; the same runs in SI units are fitted."""
    velocity = np.array([0.1, 0.15, 0.2, 0.3, 0.4, 0.5])
    columns = {"velocity": velocity, "area": 0.02 * velocity ** -0.3}
    columns["force"] = 0.5 * WATER_DENSITY * velocity**2 * columns["area"] * 1.1 * velocity ** -0.2
    table = tmp_path / "runs.csv"

    def write(values: dict) -> None:
        table.write_text("velocity_m_s,force_n,area_m2\n" + "".join(
            f"{u},{f},{a}\n" for u, f, a in zip(values["velocity"], values["force"], values["area"], strict=True)))

    write({**columns, column: columns[column] * scale})
    done = run_cli("vogel", str(table), "--json")
    assert done.returncode == 1 and said in done.stderr and "nothing was fitted" in done.stderr, done.stderr
    assert not (tmp_path / "runs.vogel.png").exists()
    write(columns)
    assert run_cli("vogel", str(table), "--json").returncode == 0


def test_a_spreadsheet_table_in_a_decimal_comma_locale_is_read_and_empty_cells_are_named(tmp_path):
    """Excel in a decimal-comma locale saves ';'-separated rows with 0,25: read as the same numbers (before:
    "needs columns ...; it has 'velocity_m_s;force_n;area_m2', None"). An empty cell was read as 0 and blamed
    on units; it is named. A --plot that is not a .png is refused (it was written as a PNG named 'none')."""
    velocity = [0.1, 0.2, 0.3, 0.45]
    rows = [(u, 0.5 * WATER_DENSITY * u**2 * 0.01 * 1.1, 0.01) for u in velocity]
    comma = tmp_path / "runs.csv"
    comma.write_text("velocity_m_s,force_n,area_m2\n" + "".join(f"{u},{f},{a}\n" for u, f, a in rows))
    expected = json.loads(run_cli("vogel", str(comma), "--json").stdout)["per_run"]
    for name, separator in (("semicolon.csv", ";"), ("tabs.tsv", "\t")):
        table = tmp_path / name
        table.write_text(separator.join(("velocity_m_s", "force_n", "area_m2")) + "\n" + "".join(
            separator.join(f"{v!r}".replace(".", ",") for v in row) + "\n" for row in rows), encoding="utf-8-sig")
        done = run_cli("vogel", str(table), "--json")
        assert done.returncode == 0, done.stderr
        assert [r["cd"] for r in json.loads(done.stdout)["per_run"]] == pytest.approx([r["cd"] for r in expected])
    comma.write_text("velocity_m_s,force_n,area_m2\n0.1,0.06,0.01\n0.2,,0.01\n0.3,0.5,0.01\n")
    empty = run_cli("vogel", str(comma))
    assert empty.returncode == 1 and "line 3: no force_n (an empty cell)" in empty.stderr, empty.stderr
    wrong = run_cli("vogel", str(tmp_path / "semicolon.csv"), "--plot", str(tmp_path / "none"))
    assert wrong.returncode == 2 and "ending in .png" in wrong.stderr and not (tmp_path / "none").exists()


def test_the_vogel_plots_log_axes_are_labelled_with_plain_numbers_at_least_twice():
    from veg_area_ros.drag import _tick_digits

    assert _tick_digits(0.09, 0.65) == (1.0, 2.0, 5.0)  # 0.1, 0.2, 0.5: no 3x10^-1 running into 4x10^-1
    assert _tick_digits(0.0035, 0.013) == (1.0, 2.0, 5.0)  # 0.005, 0.01
    assert _tick_digits(0.25, 0.45) == tuple(float(d) for d in range(1, 10))  # 0.3, 0.4: no 1, 2 or 5 between
    assert _tick_digits(0.31, 0.33) is None  # narrower than a digit's step: matplotlib's own ticks stay
