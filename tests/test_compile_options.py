"""The suite compiles its kernels with conftest.TEST_INIT_OPTIONS (on the CPU, without
Taichi's CFG optimisation, which makes the large kernels compile about ten times sooner);
circles compiles a scene of `backend.OPTIMIZE_FROM_N` circles or more with it. The two must
give the same state bit for bit, or the suite would test other kernels than the ones users
run at that size. Each case runs a scene here, with the suite's options, and in a fresh
process with the pass, and compares every array and count exactly. A last test checks the
switch itself (`backend.compile_for`) in a process of circles' own options.
"""

import json
import textwrap

import numpy as np
import pytest

from conftest import TEST_ARCH, TEST_INIT_OPTIONS
from process_util import run_script

pytestmark = pytest.mark.skipif(not TEST_INIT_OPTIONS, reason="the suite runs with circles' own options here")

# Mixed radii, about 1000 to 2000 pair collisions each, both boundaries and precisions.
SCENES = {
    "event": dict(n=1200, box=(1.2, 0.9), radius=(0.006, 0.012), speed=(0.5, 1.0), boundary="walls",
                  scheme="event", precision="f64", seed=41),
    "discrete": dict(n=1200, box=(1.2, 0.9), radius=(0.006, 0.012), speed=(0.5, 1.0), boundary="periodic",
                     scheme="discrete", precision="f32", seed=42),
}
STEPS = 40

SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    import circles
    from circles import backend

    out, kw, threads = sys.argv[2], json.loads(sys.argv[3]), sys.argv[4] == "threads"
    circles.init(arch=sys.argv[1], cfg_optimization=True)  # as circles compiles a large scene
    if threads:
        backend.SERIAL_N = 0
        backend.EVENT_SERIAL_WORK = 0
    sim = circles.Simulation(circles.Scene(**kw))
    sim.step(int(sys.argv[5]))
    s, st = sim.state(), sim.stats()
    np.savez(out, pos=s.pos, vel=s.vel, counts=np.array([st["pair_collisions"], st["wall_collisions"]]))
""")


def _scene_json(kw):
    return json.dumps({k: list(v) if isinstance(v, tuple) else v for k, v in kw.items()})


# The loops of small scenes (one thread) by default; the threads' loops (queue in parts, the
# discrete team) in the slow suite.
@pytest.mark.parametrize("loops", ["serial", pytest.param("threads", marks=pytest.mark.slow)])
@pytest.mark.parametrize("scheme", ["event", "discrete"])
def test_the_suites_compile_options_give_circles_own_bits(circles_cpu, tmp_path, monkeypatch, scheme, loops):
    kw = SCENES[scheme]
    if loops == "threads":
        monkeypatch.setattr(circles_cpu.backend, "SERIAL_N", 0)
        monkeypatch.setattr(circles_cpu.backend, "EVENT_SERIAL_WORK", 0)
    sim = circles_cpu.Simulation(circles_cpu.Scene(**kw))
    sim.step(STEPS)
    here, st = sim.state(), sim.stats()
    there = run_script(SCRIPT, TEST_ARCH, tmp_path / "default.npz", _scene_json(kw), loops, str(STEPS), timeout=600)
    assert np.array_equal(here.pos, there["pos"]) and np.array_equal(here.vel, there["vel"])
    assert [st["pair_collisions"], st["wall_collisions"]] == there["counts"].tolist()
    assert st["pair_collisions"] > 500  # the runs did collide


SWITCH_SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    import taichi as ti
    import circles
    from circles import backend

    out, kw = sys.argv[2], json.loads(sys.argv[3])
    circles.init(arch="cpu")  # circles' own options: the pass chosen by size
    runtime, config = ti.lang.impl.get_runtime(), ti.lang.impl.current_cfg()
    backend.OPTIMIZE_FROM_N = kw["n"]  # this scene counts as large
    large = circles.Simulation(circles.Scene(**kw))
    large.step(20)
    large20 = large.state().pos
    with_pass = config.cfg_optimization
    compiled = runtime.get_num_compiled_functions()
    backend.OPTIMIZE_FROM_N = 10 ** 9  # and now as small
    backend.compile_for(kw["n"])
    dropped = runtime.get_num_compiled_functions()
    small = circles.Simulation(circles.Scene(**kw))
    small.step(20)
    large.step(20)  # goes on with kernels compiled without the pass
    again = circles.Simulation(circles.Scene(**kw))
    again.step(40)
    s, l, a = small.state(), large.state(), again.state()
    np.savez(out, flags=np.array([with_pass, config.cfg_optimization, compiled, dropped]),
             small=s.pos, large20=large20, large=l.pos, again=a.pos, large_vel=l.vel, again_vel=a.vel)
""")


@pytest.mark.skipif(TEST_ARCH != "cpu", reason="the pass is chosen by size on a CPU only")
def test_a_scenes_size_chooses_the_pass_and_a_switch_drops_what_was_compiled(tmp_path):
    kw = dict(SCENES["event"], n=600)
    got = run_script(SWITCH_SCRIPT, "cpu", tmp_path / "switch.npz", _scene_json(kw), timeout=600)
    with_pass, without, compiled, dropped = got["flags"].tolist()
    assert with_pass and not without
    assert compiled > 0 and dropped == 0  # nothing compiled with the pass serves the small scene
    # The same scene 20 steps in either way, and 40 steps in across the switch, bit for bit.
    assert np.array_equal(got["small"], got["large20"])
    assert np.array_equal(got["large"], got["again"]) and np.array_equal(got["large_vel"], got["again_vel"])
