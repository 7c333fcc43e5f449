"""Scene files and sweep files made by hypothesis, each with a defect (a wrong type, a missing or
an extra key, a value out of range or not finite, broken TOML): every one is refused with exit
status 2 and one line on stderr, never a traceback, and nothing is run or written.

Each example starts from a small valid file and takes one defect, so none can be valid.
"""

import contextlib
import io
import json
import math
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from circles import cli
from circles import sweep as sweeps

FUZZ = settings(max_examples=200, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])

NONFINITE = st.sampled_from([math.nan, math.inf, -math.inf])
TEXT = st.text(alphabet="abcxyz _-.1", max_size=6)
BOOLS = st.booleans()
TABLES = st.fixed_dictionaries({"a": st.integers(0, 3)})
NOT_INTEGRAL = st.floats(0.1, 1e3).filter(lambda x: x != int(x))

SCENE = {"n": 20, "box": [4.0, 3.0], "radius": 0.1, "speed": [0.5, 1.0], "mass": "radius", "boundary": "walls",
         "scheme": "event", "precision": "f64", "seed": 1}
RUN = {"duration": 0.1, "fps": 10.0, "size": "80x60", "arch": "cpu"}
CIRCLES = {"box": [4.0, 3.0], "circle": [{"pos": [1.0, 1.0], "vel": [0.5, 0.0], "radius": 0.2},
                                         {"pos": [3.0, 1.0], "vel": [-0.5, 0.0], "radius": 0.2}]}
SWEEP = {"scene": {"n": 20, "radius": 0.05, "speed": [1.0, 1.0], "mass": "equal", "boundary": "periodic", "seed": 1},
         "vary": {"area_fraction": [0.1, 0.3]},
         "sweep": {"repeats": 2, "equilibrate": 0.1, "measure": 0.5, "blocks": 2,
                   "observables": ["compressibility", "collision_rate", "energy_change"]}}


def pair_with(bad):
    """A pair with one bad element."""
    return st.tuples(bad, st.floats(0.5, 2.0), BOOLS).map(lambda t: [t[0], t[1]] if t[2] else [t[1], t[0]])


#: Bad values of each scene key, in the base scene above (a 4 x 3 walled box, radius 0.1).
BAD_SCENE = {
    "n": st.one_of(st.integers(max_value=0), NOT_INTEGRAL, TEXT, BOOLS, NONFINITE, TABLES),
    "box": st.one_of(pair_with(st.floats(max_value=0.0)), pair_with(NONFINITE), st.floats(0.1, 10), TEXT,
                     st.lists(st.floats(1, 5), min_size=3, max_size=4), st.just([])),
    "radius": st.one_of(st.floats(max_value=0.0), NONFINITE, TEXT, BOOLS, TABLES,
                        st.floats(0.2, 0.5).map(lambda r: [r, r / 2]), st.lists(st.floats(0.01, 0.1), min_size=3,
                                                                                  max_size=3)),
    "speed": st.one_of(st.floats(max_value=-1e-9), NONFINITE, TEXT, st.floats(1e152, 1e300), pair_with(NONFINITE)),
    "mass": st.one_of(TEXT, st.integers()),
    "boundary": st.one_of(TEXT, st.integers()),
    "scheme": st.one_of(TEXT, st.integers()),
    "precision": st.one_of(TEXT, st.integers()),
    "dt": st.one_of(st.floats(max_value=0.0), NONFINITE, st.floats(1e28, 1e300), TEXT),
    "seed": st.one_of(st.integers(max_value=-1), NOT_INTEGRAL, TEXT, BOOLS),
}
#: Bad values that stay bad whatever the box (a sweep may size the box by the area fraction).
BAD_SIZED = {**BAD_SCENE, "n": st.one_of(st.integers(max_value=0), NOT_INTEGRAL, TEXT, BOOLS, NONFINITE),
             "radius": st.one_of(st.floats(max_value=0.0), NONFINITE, TEXT, BOOLS,
                                 st.floats(0.2, 0.5).map(lambda r: [r, r / 2]))}
BAD_FRACTION = st.one_of(st.floats(max_value=0.0), st.floats(0.91, 1e9), NONFINITE, TEXT)
BAD_RUN = {
    "duration": st.one_of(st.floats(max_value=0.0), NONFINITE, TEXT, st.floats(1e9, 1e300)),
    "fps": st.one_of(st.floats(max_value=0.0), NONFINITE, TEXT),
    "size": st.one_of(st.text(alphabet="ab x", max_size=5), st.just("0x10"), st.just("10x999999")),
    "arch": st.one_of(TEXT.filter(lambda a: a not in ("auto", "cpu", "gpu")), st.integers()),
    "threads": st.one_of(st.integers(max_value=-1), st.integers(10_000, 10**6), TEXT),
}
UNKNOWN = st.from_regex(r"[a-z]{2,8}", fullmatch=True)


def toml_value(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, (int, str)):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(value)


def toml_text(doc):
    """TOML of a document: top-level values first, then tables, then arrays of tables."""
    lines = [f"{k} = {toml_value(v)}" for k, v in doc.items() if not isinstance(v, dict) and not (
        isinstance(v, list) and v and all(isinstance(e, dict) for e in v))]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            lines += [f"{kk} = {toml_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list) and v and all(isinstance(e, dict) for e in v):
            for entry in v:
                lines.append(f"[[{k}]]")
                lines += [f"{kk} = {toml_value(vv)}" for kk, vv in entry.items()]
    return "\n".join(lines) + "\n"


BROKEN = st.sampled_from(["= 1", "[run", "n = ", "x = [1, 2", 'y = "abc', "n = 5\nn = 6", "[[", "a.b = 1\na = 2"])


@st.composite
def broken_toml(draw, doc):
    """A valid file with a line that breaks it, at a line boundary; or bytes that are not UTF-8."""
    if draw(st.booleans()):
        return b"\xff" + draw(st.binary(max_size=20))
    lines = toml_text(doc).splitlines()
    at = draw(st.integers(0, len(lines)))
    return "\n".join(lines[:at] + [draw(BROKEN)] + lines[at:]).encode()


@st.composite
def bad_scene_files(draw):
    kind = draw(st.sampled_from(["scene", "fraction", "unknown", "run", "run-unknown", "circle", "broken"]))
    scene, run = dict(SCENE), dict(RUN)
    if kind == "scene":
        key = draw(st.sampled_from(sorted(BAD_SCENE)))
        scene[key] = draw(BAD_SCENE[key])
    elif kind == "fraction":  # in place of the box, or beside it
        if draw(st.booleans()):
            del scene["box"]
            scene["area_fraction"] = draw(BAD_FRACTION)
        else:
            scene["area_fraction"] = draw(st.floats(0.01, 0.5))
    elif kind == "unknown":
        scene[draw(UNKNOWN.filter(lambda k: k not in BAD_SCENE and k not in ("run", "circle")))] = 1
    elif kind == "run":
        key = draw(st.sampled_from(sorted(BAD_RUN)))
        run[key] = draw(BAD_RUN[key])
    elif kind == "run-unknown":
        run[draw(UNKNOWN.filter(lambda k: k not in cli.RUN_DEFAULTS))] = 1
    elif kind == "circle":
        circles = json.loads(json.dumps(CIRCLES))
        entry = circles["circle"][draw(st.integers(0, 1))]
        what = draw(st.sampled_from(["missing", "pos", "radius", "extra", "random-key"]))
        if what == "missing":
            del entry[draw(st.sampled_from(["pos", "vel", "radius"]))]
        elif what == "pos":
            entry["pos"] = draw(st.one_of(pair_with(NONFINITE), TEXT, st.lists(st.floats(1, 2), max_size=1)))
        elif what == "radius":
            entry["radius"] = draw(st.one_of(st.floats(max_value=0.0), NONFINITE, TEXT))
        elif what == "extra":
            entry[draw(UNKNOWN.filter(lambda k: k not in ("pos", "vel", "radius", "mass", "color")))] = 1
        else:
            circles[draw(st.sampled_from(["n", "seed", "speed"]))] = 1
        return toml_text({**circles, "run": run}).encode()
    else:
        return draw(broken_toml({**scene, "run": run}))
    return toml_text({**scene, "run": run}).encode()


@st.composite
def bad_sweep_files(draw):
    doc = json.loads(json.dumps(SWEEP))
    kind = draw(st.sampled_from(["scene", "vary", "sweep", "missing", "extra", "broken"]))
    if kind == "scene":
        key = draw(st.sampled_from(sorted(BAD_SIZED)))
        doc["scene"][key] = draw(BAD_SIZED[key])
    elif kind == "vary":
        what = draw(st.sampled_from(["unknown", "empty", "not-a-list", "bad-value", "seed", "twice"]))
        if what == "unknown":
            doc["vary"][draw(UNKNOWN.filter(lambda k: k not in BAD_SCENE and k != "area_fraction"))] = [1, 2]
        elif what == "empty":
            doc["vary"]["area_fraction"] = []
        elif what == "not-a-list":
            doc["vary"]["area_fraction"] = draw(st.one_of(st.floats(0.1, 0.5), TEXT, TABLES))
        elif what == "bad-value":
            doc["vary"]["area_fraction"] = [0.2, draw(BAD_FRACTION)]
        elif what == "seed":
            doc["vary"]["seed"] = [1, 2]
        else:
            doc["vary"]["area_fraction"] = [0.2, 0.3, 0.2]
    elif kind == "sweep":
        bad = {"repeats": st.one_of(st.integers(max_value=0), st.integers(1001, 10**9), NOT_INTEGRAL, TEXT),
               "blocks": st.one_of(st.integers(max_value=0), st.integers(10_001, 10**9), NOT_INTEGRAL, BOOLS),
               "equilibrate": st.one_of(st.floats(max_value=-1e-9), NONFINITE, TEXT, st.floats(1e13, 1e300)),
               "measure": st.one_of(st.floats(max_value=0.0), NONFINITE, TEXT, st.floats(1e13, 1e300)),
               "observables": st.one_of(st.just([]), TEXT, st.lists(TEXT.filter(lambda o: o not in sweeps.OBSERVABLES),
                                                                   min_size=1, max_size=2),
                                        st.just(["compressibility", "compressibility"]), st.just(["wall_pressure"]))}
        key = draw(st.sampled_from(sorted(bad)))
        doc["sweep"][key] = draw(bad[key])
    elif kind == "missing":
        del doc[draw(st.sampled_from(["scene", "vary"]))]
    elif kind == "extra":
        where = draw(st.sampled_from(["top", "scene", "sweep"]))
        name = draw(UNKNOWN.filter(lambda k: k not in ("scene", "vary", "sweep", *BAD_SCENE, "area_fraction",
                                                       *sweeps.SWEEP_DEFAULTS)))
        (doc if where == "top" else doc[where])[name] = {"a": 1} if where == "top" else 1
    else:
        return draw(broken_toml(doc))
    return toml_text(doc).encode()


def refused(main, args, data):
    """Run `main` on a file holding `data`: exit 2, one line on stderr, nothing on stdout, no output
    written."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "file.toml"
        path.write_bytes(data)
        out = Path(tmp) / "out"
        err, std = io.StringIO(), io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
            status = main([*args[:1], str(path), *args[1:], str(out / "x.gif" if args[0] == "run" else out)])
        lines = err.getvalue().strip().splitlines()
        assert status == 2 and len(lines) == 1, (data, err.getvalue(), std.getvalue())
        assert lines[0].startswith("circles: error: ") and "Traceback" not in err.getvalue(), lines
        assert std.getvalue() == "" and not out.exists()


@FUZZ
@given(bad_scene_files())
def test_fuzzed_scene_files_are_refused_in_one_line(data):
    refused(cli.main, ["run", "--out"], data)


@FUZZ
@given(bad_sweep_files())
def test_fuzzed_sweep_files_are_refused_in_one_line(data):
    refused(sweeps.main, ["sweep", "--workers", "0", "--out"], data)
