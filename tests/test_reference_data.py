"""The project's copy of published hard-disk pressures (circles.reference) and the reduced
pressure's definition."""

import math

import pytest

from circles import reference, theory


def test_the_table_holds_each_published_series():
    li = reference.pressures("Li2022")
    assert {p.n for p in li} == {224, 870}
    assert len(reference.pressures("Li2022", n=870)) == 25 and len(reference.pressures("Li2022", n=224)) == 27
    assert {p.method for p in reference.pressures("Engel2013")} == {"MPMC", "EDMD"}
    first = reference.pressures("Li2022", n=870)[0]  # Li et al. 2022, table of N = 870
    assert (first.eta, first.beta_p_d2, first.se) == (0.670, 7.986735, 0.000026)
    assert first.aspect == pytest.approx(29 / (30 * math.sqrt(3) / 2), rel=1e-15)
    assert all(p.aspect == 1.0 for p in reference.pressures(n=224))
    assert all(0 < p.se < 0.02 for p in reference.pressures())


def test_reduced_pressure_is_z_times_rho_d_squared():
    # eta = rho pi d^2 / 4, so rho d^2 = 4 eta / pi.
    assert reference.reduced_pressure(2.0, 0.5) == pytest.approx(2.0 * 4 * 0.5 / math.pi, rel=1e-15)


def test_liu_holds_to_about_a_percent_at_0_67_and_not_beyond():
    """Where Liu's fit stops being a reference: 1.5% above the event-chain data at 0.670."""
    point = reference.pressures("Li2022", n=870)[0]
    liu = reference.reduced_pressure(theory.liu_z(point.eta), point.eta)
    assert liu / point.beta_p_d2 - 1 == pytest.approx(0.0146, abs=0.0005)


def test_a_sweep_of_the_published_n_and_box_is_set_beside_the_published_pressure(tmp_path):
    from circles import sweep as sweeps

    path = tmp_path / "melt.toml"
    path.write_text('[scene]\ncrystal = [29, 30]\nradius = 0.5\nmass = "equal"\nboundary = "periodic"\n\n'
                    '[vary]\narea_fraction = [0.670, 0.675]\n\n[sweep]\nobservables = ["reduced_pressure"]\n')
    sweep = sweeps.read_sweep(path)
    row = {"temperature": "0.5"}
    known = sweeps.theory(sweep, sweep.points[0], row)
    assert (known["reduced_pressure"], known["reduced_pressure_se"]) == (7.986735, 0.000026)
    assert "reduced_pressure" not in sweeps.theory(sweep, sweep.points[1], row)  # no published point at 0.675
    assert [p.eta for p in reference.series(870, 29 / (30 * math.sqrt(3) / 2))][:2] == [0.670, 0.672]
    assert reference.series(870, 1.0) == []  # N = 870 was published in the 29 : 30 sqrt(3)/2 box only
