"""The observables against numbers worked out by hand from their definitions (`circles.observables`),
not against another path through the same code: the temperature from the kinetic energy and the
degrees of freedom, P = Z N kT / A with the right area, the wall pressure from the wall impulse
over the open perimeter, a row's values over its interval alone. Then the same identities in a
real run: the walls' pressure and the virial's agree in a small walled box whose area with or
without a radius at each wall differs by many standard errors."""

import math

import numpy as np
import pytest

from circles import observables
from circles.writers import Run, StatsWriter, read_stats

# A hand-made pair of stats: 5 circles, box 4 x 3, mean radius 0.5, an interval from t = 1 to
# t = 3 in which the virial grows by 40 and the wall impulse by 60.
BEFORE = dict(time=1.0, kinetic_energy=12.0, momentum=(0.0, 0.0), pair_collisions=7, wall_collisions=2,
              virial=10.0, wall_impulse=15.0, max_overlap=0.0)
AFTER = dict(time=3.0, kinetic_energy=10.0, momentum=(1.0, 2.0), pair_collisions=27, wall_collisions=9,
             virial=50.0, wall_impulse=75.0, max_overlap=0.0)
N, BOX, R, TOTAL_MASS = 5, (4.0, 3.0), 0.5, 10.0


def with_temperature(stats, boundary):
    return dict(stats, temperature=observables.temperature(stats["kinetic_energy"], stats["momentum"], TOTAL_MASS,
                                                           N, boundary))


def test_temperature_counts_the_degrees_of_freedom():
    # Walls: 2 degrees of freedom a circle, kT = K / N.
    assert observables.temperature(10.0, (1.0, 2.0), TOTAL_MASS, N, "walls") == 2.0
    # Periodic: the centre of mass holds |P|^2 / 2M = 5 / 20 = 0.25; 2(N - 1) degrees are left.
    assert observables.temperature(10.0, (1.0, 2.0), TOTAL_MASS, N, "periodic") == pytest.approx(9.75 / 4, rel=1e-15)
    assert math.isnan(observables.temperature(1.0, (0.5, 0.0), 1.0, 1, "periodic"))


def test_a_walled_rows_pressures_use_the_area_and_perimeter_open_to_the_centres():
    row = observables.interval(with_temperature(BEFORE, "walls"), with_temperature(AFTER, "walls"), N, BOX, "walls", R)
    # Open to the centres: 3 x 2 (area 6, perimeter 10); over t = 2, kT = 2, N kT = 10.
    assert row["compressibility"] == pytest.approx(1 + 40 / (2 * 2 * 10), rel=1e-15)  # 2.0
    assert row["pressure"] == pytest.approx(2.0 * 10 / 6, rel=1e-15)
    assert row["wall_pressure"] == pytest.approx(60 / (2 * 10), rel=1e-15)  # 3.0
    assert row["temperature"] == 2.0
    assert row["collision_rate"] == pytest.approx(2 * 20 / (N * 2), rel=1e-15)
    assert (row["pair_collisions"], row["wall_collisions"], row["time"]) == (27, 9, 3.0)  # totals at the end


def test_a_periodic_rows_pressure_uses_the_whole_box_and_the_centre_of_mass_frame():
    row = observables.interval(with_temperature(BEFORE, "periodic"), with_temperature(AFTER, "periodic"), N, BOX,
                               "periodic", R)
    kT = 9.75 / 4
    # P A = N kT + virial / 2t over the box's own area 12.
    assert row["pressure"] == pytest.approx((N * kT + 40 / 4) / 12, rel=1e-15)
    assert row["compressibility"] == pytest.approx(1 + 40 / (4 * N * kT), rel=1e-15)
    assert math.isnan(row["wall_pressure"])


def test_a_row_holds_its_interval_alone_and_the_totals_since_the_start():
    start = dict(BEFORE, time=0.0, virial=0.0, wall_impulse=0.0, pair_collisions=0)
    walls = [with_temperature(s, "walls") for s in (start, BEFORE, AFTER)]
    first = observables.interval(walls[0], walls[1], N, BOX, "walls", R)
    second = observables.interval(walls[1], walls[2], N, BOX, "walls", R)
    # The first interval, t = 0 to 1: virial 10, wall impulse 15, 7 collisions, kT 12 / 5.
    assert first["compressibility"] == pytest.approx(1 + 10 / (2 * 1 * 12), rel=1e-15)
    assert first["wall_pressure"] == pytest.approx(15 / (1 * 10), rel=1e-15)
    assert first["collision_rate"] == pytest.approx(2 * 7 / (N * 1), rel=1e-15)
    # The second, t = 1 to 3, not 0 to 3: virial 40, not 50.
    assert second["compressibility"] == pytest.approx(2.0, rel=1e-15)
    since = observables.since_start(walls[2], N, BOX, "walls", R)
    assert since["compressibility"] == pytest.approx(1 + 50 / (2 * 3 * 10), rel=1e-15)
    assert since["wall_pressure"] == pytest.approx(75 / (3 * 10), rel=1e-15)


def test_no_pressure_over_no_time():
    row = observables.interval(with_temperature(AFTER, "walls"), with_temperature(AFTER, "walls"), N, BOX, "walls", R)
    assert all(math.isnan(row[k]) for k in ("pressure", "compressibility", "wall_pressure", "collision_rate"))


def test_simulation_temperature_in_the_centre_of_mass_frame(circles_cpu):
    """A periodic box given a drift: the temperature is that of the motion about the centre of
    mass, over N - 1, computed here from the velocities; walls keep K / N."""
    rng = np.random.default_rng(4)
    n = 30
    pos = np.stack(np.meshgrid(np.arange(6) + 0.5, np.arange(5) + 0.5), -1).reshape(-1, 2)
    vel = rng.normal(size=(n, 2)) + [3.0, -1.0]
    mass = rng.uniform(1.0, 2.0, n)
    for boundary in ("periodic", "walls"):
        sim = circles_cpu.Simulation.from_arrays(pos, vel, 0.2, mass=mass, box=(6.0, 5.0), boundary=boundary)
        st = sim.stats()
        centre = (mass[:, None] * vel).sum(0) / mass.sum()
        kinetic = 0.5 * np.sum(mass[:, None] * vel ** 2)
        about = 0.5 * np.sum(mass[:, None] * (vel - centre) ** 2)
        expect = about / (n - 1) if boundary == "periodic" else kinetic / n
        assert st["temperature"] == pytest.approx(expect, rel=1e-12)


def test_walls_and_virial_give_one_pressure_in_a_small_walled_box(circles_cpu, tmp_path):
    """36 disks of radius 0.5 in a 7 x 7 box: the area open to the centres, 6 x 6, is 27%
    below the box's, and a radius off the area (6.5 x 6.5) moves the virial's pressure by 17%.
    Over 40 intervals of 2 time units the difference between the two pressures has a standard
    error of about 1%, so either mistake shows by many standard errors."""
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=36, box=(7.0, 7.0), radius=0.5, speed=(1.0, 1.0),
                                                   mass="equal", seed=11))
    sim.advance(20.0)
    with StatsWriter(tmp_path / "walls.csv") as table:
        for _ in Run(sim, 80.0, 0.5, at_interval=[table]):
            pass
    rows = read_stats(tmp_path / "walls.csv")
    virial, wall = rows["pressure"], rows["wall_pressure"]
    difference = wall - virial
    se = np.std(difference, ddof=1) / math.sqrt(difference.size)
    mean_p = float(np.mean(virial))
    assert se < 0.03 * mean_p  # resolving a 17% error by far
    assert abs(np.mean(difference)) < 4 * se, (np.mean(wall), mean_p, se)
    # The identity P = Z N kT / A, row by row, with A the open area.
    np.testing.assert_allclose(virial, rows["compressibility"] * 36 * rows["temperature"] / 36.0, rtol=1e-12)


class _Frames:
    """A frame writer that records what it is given."""

    def __init__(self, wants_row=True):
        self.wants_row = wants_row
        self.got = []

    def write(self, *args):
        if len(args) == 1:  # an interval writer: the row alone
            self.got.append(args[0])
        else:
            sim, row, stats = args
            self.got.append((sim.time, row, stats))


def test_a_run_gives_each_frame_the_row_of_the_interval_that_ended_then(circles_cpu):
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=30, box=(3.0, 3.0), radius=0.1, seed=2))
    frames, rows = _Frames(), []

    class Table:
        def write(self, row):
            rows.append(row)

    for _ in Run(sim, 1.0, 4, at_frame=[frames], at_interval=[Table()]):
        pass
    times = [t for t, _, _ in frames.got]
    assert times == [0.0, 0.25, 0.5, 0.75] and len(rows) == 4
    assert all("hexatic_order" not in row for row in rows)  # not measured unless asked for
    assert frames.got[0][1]["time"] == 0.0 and math.isnan(frames.got[0][1]["pressure"])
    for k in range(1, 4):
        assert frames.got[k][1] is rows[k - 1]  # frame k: the row of the interval ending at its instant
        assert frames.got[k][2]["time"] == times[k]  # and the stats taken then


def test_a_run_takes_no_stats_when_no_writer_needs_them(circles_cpu, monkeypatch):
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=30, box=(3.0, 3.0), radius=0.1, seed=2))
    calls = []
    original = type(sim).stats
    monkeypatch.setattr(type(sim), "stats", lambda self: calls.append(1) or original(self))
    video = _Frames(wants_row=False)
    run = Run(sim, 0.5, 4, at_frame=[video])
    for _ in run:
        pass
    assert calls == [] and not run.need_stats
    assert all(row is None and stats is None for _, row, stats in video.got)
    measuring = Run(sim, 0.5, 4, at_frame=[_Frames(wants_row=False)], at_interval=[_Frames()])
    assert measuring.need_stats and len(calls) == 1  # the stats at the start
    assert Run(sim, 0.5, 4, at_frame=[_Frames()]).need_stats  # a frame writer that wants rows

    class Plain:  # a writer that does not say: it gets rows
        def write(self, sim, row, stats):
            pass

    assert Run(sim, 0.5, 4, at_frame=[Plain()]).need_stats
    assert not Run(sim, 0.5, 4, at_frame=[_Frames()], need_stats=False).need_stats


def test_two_circles_in_a_periodic_box_have_one_degree_pair_of_heat():
    # 2(N - 1) = 2 degrees of freedom: kT = (K - |P|^2 / 2M) / 1.
    assert observables.temperature(3.0, (2.0, 0.0), 4.0, 2, "periodic") == pytest.approx(2.5, rel=1e-15)


def test_circles_at_rest_have_no_pressure():
    still = dict(AFTER, kinetic_energy=0.0, momentum=(0.0, 0.0), temperature=0.0)
    got = observables.pressures(2.0, 40.0, 60.0, 0.0, N, BOX, "walls", R)
    assert math.isnan(got["pressure"]) and math.isnan(got["compressibility"])
    assert got["wall_pressure"] == pytest.approx(60 / (2 * 10), rel=1e-15)  # the walls' impulse alone
    assert math.isnan(observables.since_start(still, N, BOX, "walls", R)["compressibility"])


def test_pressures_since_the_start_of_a_periodic_box_use_the_whole_box():
    after = with_temperature(AFTER, "periodic")
    kT = 9.75 / 4
    got = observables.since_start(after, N, BOX, "periodic", R)
    assert got["pressure"] == pytest.approx((N * kT + 50 / 6) / 12, rel=1e-15)  # virial 50 over t = 3
    assert math.isnan(got["wall_pressure"])


def test_a_row_carries_the_momentum_at_its_end():
    row = observables.interval(with_temperature(BEFORE, "walls"), with_temperature(AFTER, "walls"), N, BOX, "walls", R)
    assert (row["momentum_x"], row["momentum_y"], row["kinetic_energy"]) == (1.0, 2.0, 10.0)


class _Clock:
    """A clock that moves by one second at each reading."""

    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        self.now += 1.0
        return self.now


def _row(k):
    row = dict.fromkeys(observables.COLUMNS, 0.5 * k)
    row.update(pair_collisions=3 * k, wall_collisions=k, wall_pressure=math.nan if k % 2 else 1.25)
    return row


def test_a_stats_table_counts_its_rows_and_its_own_time_and_reads_back(tmp_path, monkeypatch):
    from circles import writers

    clock = _Clock()
    monkeypatch.setattr(writers.time, "perf_counter", clock)
    path = tmp_path / "t.csv"
    with StatsWriter(path) as table:
        for k in range(3):
            table.write(_row(k))
    assert table.rows == 3 and table.seconds == 3.0  # one clock step inside each write
    back = read_stats(path)
    assert list(back) == list(observables.COLUMNS)
    np.testing.assert_array_equal(back["pair_collisions"], [0, 3, 6])
    np.testing.assert_array_equal(back["wall_pressure"], [1.25, math.nan, 1.25])  # NaN as an empty cell


def test_an_empty_last_cell_reads_as_nan(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("time,wall_pressure\n1.0,\n2.0,3.5\n")
    back = read_stats(path)
    np.testing.assert_array_equal(back["wall_pressure"], [math.nan, 3.5])


def test_a_stats_table_lets_an_error_through(tmp_path):
    with pytest.raises(KeyError):
        with StatsWriter(tmp_path / "t.csv") as table:
            table.write({})  # no columns


def test_a_run_counts_the_time_its_stats_take(circles_cpu, monkeypatch):
    from circles import writers

    sim = circles_cpu.Simulation(circles_cpu.Scene(n=30, box=(3.0, 3.0), radius=0.1, seed=2))
    run = Run(sim, 0.5, 4, at_interval=[_Frames()])
    assert run.stats_seconds == 0.0
    monkeypatch.setattr(writers.time, "perf_counter", _Clock())
    for _ in run:
        pass
    assert run.stats_seconds == 2.0  # two intervals, one clock step around each one's stats


def test_the_reduced_pressure_of_equal_disks():
    walls = observables.interval(with_temperature(BEFORE, "walls"), with_temperature(AFTER, "walls"), N, BOX,
                                 "walls", R, 1.0)
    assert walls["reduced_pressure"] == pytest.approx((20 / 6) * 1.0 ** 2 / 2.0, rel=1e-15)  # P d^2 / kT
    kT = 9.75 / 4
    periodic = observables.interval(with_temperature(BEFORE, "periodic"), with_temperature(AFTER, "periodic"), N,
                                    BOX, "periodic", R, 0.5)
    assert periodic["reduced_pressure"] == pytest.approx((N * kT + 10) / 12 * 0.25 / kT, rel=1e-15)
    assert math.isnan(observables.interval(with_temperature(BEFORE, "walls"), with_temperature(AFTER, "walls"), N,
                                           BOX, "walls", R)["reduced_pressure"])  # no common diameter
    assert observables.equal_diameter([0.5, 0.5]) == 1.0 and observables.equal_diameter([0.5, 0.6]) is None
    assert observables.equal_diameter([0.5]) == 1.0 and observables.equal_diameter([]) is None  # one circle, none


def test_a_simulations_reduced_pressure_is_z_rho_d_squared(circles_cpu):
    from circles import reference

    eta = 0.5
    sim = circles_cpu.Simulation(circles_cpu.Scene(n=200, area_fraction=eta, radius=0.5, speed=1.0, mass="equal",
                                                   boundary="periodic", seed=4))
    sim.advance(5.0)
    st = sim.stats()
    w, h = sim.box
    expect = reference.reduced_pressure(st["compressibility"], 200 * math.pi * 0.25 / (w * h))
    assert st["reduced_pressure"] == pytest.approx(expect, rel=1e-12)
    assert abs(200 * math.pi * 0.25 / (w * h) - eta) < 1e-12
    mixed = circles_cpu.Simulation(circles_cpu.Scene(n=50, box=(6.0, 6.0), radius=(0.1, 0.2), seed=4))
    mixed.advance(1.0)
    assert math.isnan(mixed.stats()["reduced_pressure"])


def test_a_runs_rows_carry_the_reduced_pressure_and_when_asked_the_hexatic_order(circles_cpu, tmp_path):
    """Equal disks: each row's beta P d^2 is P d^2 / kT with d their diameter; with order=True
    the table has a hexatic_order column, |psi_6| of the positions at each row's end."""
    from circles import order

    sim = circles_cpu.Simulation(circles_cpu.Scene(n=60, area_fraction=0.4, radius=0.25, speed=1.0, mass="equal",
                                                   boundary="periodic", seed=3))
    ends = []

    class Positions:
        def write(self, row):
            ends.append(order.hexatic_order(order.psi6(sim.state().pos, sim.box, True)))

    with StatsWriter(tmp_path / "o.csv", order=True) as table:
        for _ in Run(sim, 1.0, 4, at_interval=[table, Positions()], order=True):
            pass
    rows = read_stats(tmp_path / "o.csv")
    assert list(rows)[-1] == "hexatic_order"
    np.testing.assert_allclose(rows["hexatic_order"], ends, rtol=1e-15)
    np.testing.assert_allclose(rows["reduced_pressure"], rows["pressure"] * 0.5 ** 2 / rows["temperature"],
                               rtol=1e-12)
    with StatsWriter(tmp_path / "plain.csv") as table:
        for _ in Run(sim, 0.5, 4, at_interval=[table]):
            pass
    assert "hexatic_order" not in read_stats(tmp_path / "plain.csv")
