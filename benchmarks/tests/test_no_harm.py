"""The cases and the gain of benchmarks/no_harm.py."""

import math

import numpy as np
import pytest

import no_harm as nh


def test_cases_are_seeded_and_cover_every_combination_equally():
    a, b = nh.make_case(3, 7), nh.make_case(3, 7)
    np.testing.assert_array_equal(a[2], b[2])
    assert not np.array_equal(a[2], nh.make_case(4, 7)[2])
    combos = [(c["scene"], c["size"], c["blur"]) for c in (nh.make_case(0, k)[0] for k in range(18))]
    assert len(set(combos)) == 18  # 2 kinds x 3 sizes x 3 blur classes, once each in every 18 cases
    for k in range(18):
        case, sharp, blurred, cp = nh.make_case(0, k)
        assert blurred.shape == sharp.shape and blurred.dtype == np.float32
        assert 0.0 <= blurred.min() and blurred.max() <= 1.0
        want = {"unblurred": (0.0, 0.0), "barely blurred": (0.3, 0.3), "blurred": (0.8, 2.5)}[case["blur"]]
        assert want[0] <= case["extent"] <= want[1] and cp.any() == (case["extent"] > 0)
        assert case["p_z"] == bool(cp[:, 2].any())
        if case["blur"] == "unblurred" and case["noise"] == 0:
            np.testing.assert_array_equal(blurred, sharp)


def test_gain_is_the_ratio_of_the_errors_in_db():
    sharp = np.zeros((2, 2, 4, 4))
    assert nh.gain_db(sharp, sharp + 0.1, sharp + 0.01) == pytest.approx(20.0)
    assert nh.gain_db(sharp, sharp + 0.01, sharp + 0.1) == pytest.approx(-20.0)
    assert nh.gain_db(sharp, sharp, sharp) == 0.0  # an exact input returned exactly
    assert nh.gain_db(sharp, sharp, sharp + 1e-6) == -math.inf  # any change to an exact input is a loss


def test_quick_run_writes_its_table(tmp_path):
    out = tmp_path / "t.md"
    nh.main(["--quick", "--out", str(out)])
    text = out.read_text()
    assert text.startswith("# Do no harm beyond the evaluation set") and "Machine:" in text
    assert "## By blur" in text and "| unblurred | 2 |" in text  # both quick cases are unblurred
    assert text.count("unblurred (0.00)") == 2  # one row each in the per-case table
