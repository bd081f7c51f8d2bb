"""The table of benchmarks/angular_tv.py: means and worst gains by group, from the rows it is given."""

from angular_tv import PRIORS, summary  # benchmarks/angular_tv.py, on the path by conftest.py


def test_summary_gives_each_groups_mean_and_worst_gain():
    labels = [label for label, _, _ in PRIORS]
    rows = [{"case": "a", "group": "rendered", **{k: (1.0 + i, 2.0) for i, k in enumerate(labels)}},
            {"case": "b", "group": "rendered", **{k: (3.0 + i, 4.0) for i, k in enumerate(labels)}},
            {"case": "c", "group": "F01", **{k: (-1.0, 1.0) for k in labels}}]
    lines = summary(rows)
    assert len(lines) == 2 + 3  # header, rule, all, rendered, F01 (no Illum case: no row)
    cells = {line.split(" | ")[0].lstrip("| "): line.split(" | ") for line in lines[2:]}
    assert cells["rendered"][2] == "+2.00 (+1.00)"  # first prior: mean of 1 and 3, worst 1
    assert cells["rendered"][5] == "+5.00 (+4.00)"  # the last prior: 4 and 6
    assert cells["all"][2] == "+1.00 (-1.00)"
    assert cells["F01"][-1].rstrip(" |") == "1.0, 1.0 / 1.0, 1.0"
    assert cells["all"][-1].rstrip(" |") == "2.3, 4.0 / 2.3, 4.0"
