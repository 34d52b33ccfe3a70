"""The MF-IAE fuzzy system against scikit-fuzzy's control API on the same rules."""
import numpy as np
import pytest
import skfuzzy
from skfuzzy import control as ctrl

from estimators.fuzzy import RULES, MamdaniFuzzy


def skfuzzy_system(fz: MamdaniFuzzy):
    """The same Mamdani system built with scikit-fuzzy (min AND, clip, max, centroid)."""
    fuzz = skfuzzy
    uni_in = np.linspace(0, 2, 4001)
    ct = ctrl.Antecedent(uni_in, "c_t")
    ci = ctrl.Antecedent(uni_in, "c_i")
    m = ctrl.Consequent(fz.grid, "m", defuzzify_method="centroid")
    for var in (ct, ci):
        for name, c in zip(("NP", "ZE", "GA"), fz.in_centers):
            var[name] = fuzz.gaussmf(uni_in, c, fz.in_sigma)
    c, a = fz.out_center, fz.out_slope
    m["DI"] = fuzz.sigmf(fz.grid, -c, -a)
    m["MA"] = fuzz.psigmf(fz.grid, -c, a, c, -a)
    m["AU"] = fuzz.sigmf(fz.grid, c, a)
    rules = [ctrl.Rule(ct[t] & ci[i], m[o]) for t, row in RULES.items() for i, o in row.items()]
    return ctrl.ControlSystemSimulation(ctrl.ControlSystem(rules))


@pytest.mark.parametrize("fz", [MamdaniFuzzy(), MamdaniFuzzy(in_sigma=0.5, out_slope=6.0, n_out=101)])
def test_mamdani_equals_scikit_fuzzy(fz):
    sim = skfuzzy_system(fz)
    rng = np.random.default_rng(3)
    ours_all, ref_all = [], []
    for c_t, c_i in rng.uniform(0.01, 5.0, size=(60, 2)):
        s = (c_t + c_i) / 2
        sim.input["c_t"], sim.input["c_i"] = c_t / s, c_i / s      # the normalisation
        sim.compute()
        ours_all.append(fz(c_t, c_i))
        ref_all.append(sim.output["m"])
    # scikit-fuzzy interpolates input memberships on its grid: agreement to ~1e-4
    np.testing.assert_allclose(ours_all, ref_all, atol=2e-3)
    assert np.ptp(ref_all) > 0.3               # the comparison covers a real range


def test_mamdani_properties():
    fz = MamdaniFuzzy()
    assert abs(fz(1.0, 1.0)) < 1e-12                       # no mismatch: no adjustment
    assert fz(0.5, 2.0) < -0.1 and fz(2.0, 0.5) > 0.1      # sign of C_T - C_I (eq 38)
    a, b = np.random.default_rng(0).uniform(0.1, 3, (2, 50))
    np.testing.assert_allclose(fz(a, b), -fz(b, a), atol=1e-12)   # antisymmetric rules
    np.testing.assert_allclose(fz(3 * a, 3 * b), fz(a, b), atol=1e-12)  # scale-free
    assert np.all(np.abs(fz(a, b)) < 1)
    with pytest.raises(ValueError):
        MamdaniFuzzy(in_sigma=0.0)
