"""The project's copy of published hard-disk pressures (circles.reference) and the reduced
pressure's definition."""

import math

import numpy as np
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


def test_the_table_is_filtered_by_source_method_and_n_and_keeps_each_estimator():
    edmd = reference.pressures("Engel2013", "EDMD")
    assert len(edmd) == 24 and {(p.method, p.estimator) for p in edmd} == {("EDMD", "virial formula")}
    assert {p.estimator for p in reference.pressures("Engel2013", "MPMC")} == {"fitting g(r)"}
    assert {p.estimator for p in reference.pressures("Li2022")} == {"rift formula"}
    assert reference.pressures("Li2022", "EDMD") == [] and reference.pressures(n=225) == []
    assert len(reference.pressures()) == 112


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


# The exact low-density expansion of hard disks, Z = 1 + b2 eta + b3 eta^2 + ...: b2 = 2 and
# b3 = 4 (4/3 - sqrt(3)/pi) = 3.12802 (the second and third virial coefficients).
B2, B3 = 2.0, 4 * (4 / 3 - math.sqrt(3) / math.pi)


@pytest.mark.parametrize("z", [theory.liu_z, theory.henderson_compressibility])
def test_the_equations_of_state_have_the_exact_virial_coefficients_at_low_density(z):
    # Both fits give b3 = 3 + 1/8 = 3.125, 0.1% from the exact value.
    h = 1e-4
    b2 = (z(h) - z(-h)) / (2 * h)  # central differences: errors of order h^2
    b3 = (z(h) - 2 * z(0.0) + z(-h)) / (2 * h * h)
    assert z(0.0) == 1.0
    assert b2 == pytest.approx(B2, rel=1e-7)
    assert b3 == pytest.approx(B3, rel=2e-3)
    assert b3 != pytest.approx(B3, rel=5e-4)  # the fits' own b3, not the exact one


def test_henderson_and_liu_part_by_liu_s_higher_terms():
    # Liu's numerator adds eta^3/18 - 4 eta^4/21 to Henderson's: 0.0038 at eta = 0.5 over (1 - eta)^2.
    assert theory.liu_z(0.5) - theory.henderson_compressibility(0.5) == pytest.approx(
        (0.5 ** 3 / 18 - 4 * 0.5 ** 4 / 21) / 0.25, rel=1e-12)
    assert theory.henderson_compressibility(0.5) == pytest.approx((1 + 1 / 32) / 0.25, rel=1e-15)


def test_the_contact_value_is_one_in_the_ideal_gas_and_gives_back_z():
    assert theory.contact_g(1e-6) == pytest.approx(1.0, abs=1e-5)
    # Its slope at zero is b3 / 2 (g = 1 + (b3 / 2) eta + ...), Liu's b3 = 3.125.
    assert (theory.contact_g(2e-4) - theory.contact_g(1e-4)) / 1e-4 == pytest.approx(3.125 / 2, rel=1e-3)
    for eta in (0.1, 0.4, 0.7):
        assert 1 + 2 * eta * theory.contact_g(eta) == pytest.approx(theory.liu_z(eta), rel=1e-14)


def test_enskog_s_collision_rate_is_the_ideal_gas_rate_times_the_contact_value():
    """In 2D two disks meet when their centres come within sigma: a band 2 sigma wide, swept at
    the relative speed, whose mean is that of a Rayleigh distribution of scale sqrt(2 kT / m)."""
    rho, sigma, kT, m, g = 0.3, 1.5, 0.7, 2.0, 1.8
    s = math.sqrt(2 * kT / m)
    v = np.linspace(0.0, 40 * s, 400001)
    density = v / s ** 2 * np.exp(-v * v / (2 * s * s))
    mean_speed = float(np.sum(v * density) * (v[1] - v[0]))  # the Rayleigh mean, summed
    assert theory.enskog_collision_rate(rho, sigma, 1.0, kT, m) == pytest.approx(rho * 2 * sigma * mean_speed, rel=1e-6)
    assert theory.enskog_collision_rate(rho, sigma, g, kT, m) == pytest.approx(
        g * theory.enskog_collision_rate(rho, sigma, 1.0, kT, m), rel=1e-15)
    eta = 0.45
    assert theory.enskog_rate(eta, rho, sigma, kT, m) == pytest.approx(
        theory.enskog_collision_rate(rho, sigma, theory.contact_g(eta), kT, m), rel=1e-15)


def test_enskog_s_diffusion_times_the_collision_rate_is_kt_over_m():
    """D_E omega_E = kT / m at any density and contact value: D = <v^2> / (2 omega) in 2D, a
    mean free time of 1 / omega (the first Chapman-Enskog approximation)."""
    for rho, sigma, g, kT, m in [(0.3, 1.5, 1.8, 0.7, 2.0), (0.05, 1.0, 1.0, 1.0, 1.0), (0.8, 0.4, 5.0, 2.5, 0.3)]:
        d = theory.enskog_diffusion(rho, sigma, g, kT, m)
        assert d * theory.enskog_collision_rate(rho, sigma, g, kT, m) == pytest.approx(kT / m, rel=1e-14)
        assert d == pytest.approx(math.sqrt(kT / (math.pi * m)) / (2 * rho * sigma * g), rel=1e-15)
