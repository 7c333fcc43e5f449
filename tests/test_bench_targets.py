"""bench/targets.py: the performance targets judged on a benchmark run's tables.

Synthetic runs at and around each threshold, and the kept runs' CSVs under outputs/bench, whose
figures the README quotes."""
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("bench_targets", ROOT / "bench" / "targets.py")
targets = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(targets)


def _throughput(n, scheme, median, collisions=0.0, precision="f32"):
    return dict(n=n, scheme=scheme, precision=precision, circle_steps_per_s_median=median,
                circle_steps_per_s_min=0.8 * median, circle_steps_per_s_max=1.2 * median,
                pair_collisions_per_s=collisions)


def _passing_run():
    """Tables of a run that meets every CPU target, each figure just on its side of the threshold."""
    throughput = []
    for n in (10_000, 100_000, 1_000_000):
        throughput.append(_throughput(n, "discrete", 41e6))
        throughput.append(_throughput(n, "event", 15.5e6, collisions=5.1e6))
    # A slower f64 row must not stand in for the f32 one.
    throughput.append(_throughput(1_000_000, "discrete", 1e6, precision="f64"))
    placement = [dict(n=1_000_000, area_fraction=0.3, place_s_median=9.0, place_s_min=9.0, place_s_max=9.0),
                 dict(n=1_000_000, area_fraction=0.5, place_s_median=2.9, place_s_min=2.8, place_s_max=3.2),
                 dict(n=1_000_000, area_fraction=0.8, place_s_median=19.0, place_s_min=19.0, place_s_max=19.0)]
    render = [dict(n=1_000_000, frame_s_median=0.09, frame_s_min=0.08, frame_s_max=0.2)]
    memory = [dict(n=1_000_000, scheme="event", precision="f32", bytes_per_circle=0, array_bytes_per_circle=174),
              dict(n=10_000_000, scheme="discrete", precision="f32", bytes_per_circle=111,
                   array_bytes_per_circle=132),
              dict(n=10_000_000, scheme="event", precision="f32", bytes_per_circle=199, array_bytes_per_circle=174)]
    spread = [dict(n=10_000, scheme="discrete", cost_ratio=1.2), dict(n=10_000, scheme="event", cost_ratio=2.9)]
    peers = [dict(peer="pymunk", n=100_000, circle_steps_per_s_median=1e6),
             dict(peer="ratio", n=100_000, scheme="discrete", precision="f32", circle_steps_ratio=31.0,
                  ratio_min=25.0, ratio_max=33.0),
             dict(peer="ratio", n=100_000, scheme="event", precision="f32", circle_steps_ratio=8.0,
                  ratio_min=7.0, ratio_max=9.0)]
    return dict(throughput=throughput, placement=placement, render=render, memory=memory, spread=spread,
                peers=peers)


def _verdicts(tables, arch="cpu"):
    return [met for _, _, met in targets.evaluate(tables, arch)]


def test_a_run_that_meets_every_cpu_target():
    rows = targets.evaluate(_passing_run())
    assert len(rows) == 8
    assert [met for _, _, met in rows] == ["yes"] * 8
    # The figures quoted are the run's medians with their ranges.
    assert rows[0][1] == "41 M [32.8 M, 49.2 M]"
    assert rows[1][1] == "15.5 M [12.4 M, 18.6 M] and 5.1 M collisions/s"


@pytest.mark.parametrize("target, change", [
    (0, lambda t: t["throughput"][4].update(circle_steps_per_s_median=39.9e6)),   # discrete 1e6
    (1, lambda t: t["throughput"][5].update(pair_collisions_per_s=4.9e6)),        # event collisions
    (1, lambda t: t["throughput"][5].update(circle_steps_per_s_median=14.9e6)),   # event speed
    (2, lambda t: t["peers"][1].update(circle_steps_ratio=29.9)),                 # pymunk ratio
    (3, lambda t: t["throughput"][0].update(circle_steps_per_s_median=41e6 * 1.51)),  # flatness
    (4, lambda t: t["placement"][1].update(place_s_median=3.0)),                  # 3 s is not under 3 s
    (4, lambda t: t["placement"][2].update(place_s_median=20.5)),
    (5, lambda t: t["render"][0].update(frame_s_median=0.1)),
    (6, lambda t: t["memory"][2].update(bytes_per_circle=201)),                   # peak at the largest N
    (6, lambda t: t["memory"][1].update(array_bytes_per_circle=200.5)),
    (7, lambda t: t["spread"][1].update(cost_ratio=3.01)),
])
def test_each_target_fails_past_its_threshold(target, change):
    tables = _passing_run()
    change(tables)
    verdicts = _verdicts(tables)
    assert verdicts[target] == "no"
    assert verdicts[:target] + verdicts[target + 1:] == ["yes"] * 7


def test_the_memory_target_reads_the_largest_n_only():
    tables = _passing_run()
    tables["memory"][0]["bytes_per_circle"] = 500  # at 1e6 the runtime's pool hides the arrays
    assert _verdicts(tables)[6] == "yes"


def test_sections_a_run_left_out_are_not_measured():
    tables = _passing_run()
    for name in ("placement", "render", "memory", "spread", "peers"):
        del tables[name]
    tables["throughput"] = [t for t in tables["throughput"] if t["n"] != 10_000]
    assert _verdicts(tables) == ["yes", "yes"] + ["not measured"] * 6
    assert _verdicts({}) == ["not measured"] * 8


def test_gpu_target():
    tables = dict(throughput=[_throughput(10_000_000, "discrete", 5.1e9), _throughput(10_000_000, "event", 1.1e9),
                              _throughput(100_000_000, "discrete", 4e9)])
    assert _verdicts(tables, "gpu") == ["yes"]
    tables["throughput"][1]["circle_steps_per_s_median"] = 0.19e9
    assert _verdicts(tables, "gpu") == ["no"]
    del tables["throughput"][2]  # 1e8 did not run
    assert _verdicts(tables, "gpu") == ["not measured"]


def test_kept_runs_read_back_from_their_csvs():
    """The CSVs of the kept CPU runs, read back as strings, give the figures the README quotes."""
    amd, arch = targets.read_run(ROOT / "outputs" / "bench" / "amd-epyc")
    assert arch == "cpu"
    rows = targets.evaluate(amd, arch)
    assert [met for _, _, met in rows] == ["yes", "no", "yes", "yes", "yes", "yes", "yes", "yes"]
    assert rows[0][1].startswith("49.9 M [44.8 M, 51.5 M]")
    assert rows[2][1].startswith("discrete 41.4 times [38.2, 53.5]")
    intel, arch = targets.read_run(ROOT / "outputs" / "bench" / "intel-xeon-processor")
    rows = targets.evaluate(intel, arch)
    assert [met for _, _, met in rows] == ["yes", "no", "yes", "yes", "yes", "yes", "yes", "yes"]
    assert rows[0][1] == "49.6 M [48.6 M, 51.1 M]"
    assert rows[1][1] == "15.2 M [14.9 M, 15.6 M] and 1.48 M collisions/s"
    assert rows[2][1].startswith("discrete 43.5 times [27.5, 46.1]")
    assert rows[3][1] == "discrete 1.50 (1e4 against 1e5); event 1.28 (1e5 against 1e6)"
