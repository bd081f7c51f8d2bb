"""Batch simulation and deblurring on a real dask LocalCluster (2 single-threaded worker processes).

The cluster is started by a fixture and closed after the module; nothing needs to run beforehand.
"""

from __future__ import annotations

import os
import json
import signal
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")
pytestmark = pytest.mark.filterwarnings("ignore::napari_lfdeblur.io.ViewOrderWarning")  # random test scenes

from napari_lfdeblur import (blind_deblur, read_lightfield, read_lightfield_with_metadata, simulate_blur,  # noqa: E402
                            write_lightfield)
from napari_lfdeblur.batch import deblur_many, item_seed, read_manifest, simulate_dataset, simulate_item  # noqa: E402
from napari_lfdeblur.blind import BlindParams  # noqa: E402
from napari_lfdeblur.cli import main  # noqa: E402
from napari_lfdeblur._cli_batch import weak_blur_summary  # noqa: E402
from napari_lfdeblur.path import load_path_json  # noqa: E402

TINY = BlindParams.preset("default").replace(
    path={"n_outer": 1, "n_restarts": 1, "n_random": 10, "n_random_later": 5, "steps": 5, "estimate_z": False,
          "min_size": 8},
    final={"n_iter": 2},
)


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        with distributed.Client(c) as cl:
            yield cl


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("inputs")
    rng = np.random.default_rng(0)
    paths = []
    for i in range(3):
        paths.append(write_lightfield(folder / f"scene{i}.npz", rng.random((3, 3, 8, 8, 3)).astype(np.float32)))
    return paths


def _serial(fn):
    """Run ``fn`` with one torch thread, as the batch tasks do."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return fn()
    finally:
        torch.set_num_threads(n)


def _lines(out):
    return (Path(out) / "manifest.jsonl").read_text().splitlines()


def _leftovers(out):
    return sorted(p.name for p in Path(out).iterdir() if ".tmp" in p.name)


def test_simulate_equals_the_serial_api_bit_for_bit(client, inputs, tmp_path):
    report = simulate_dataset(inputs, tmp_path, n_per_input=2, path_kind="shake", extent=(1.0, 3.0),
                              infinity_disparity=0.5, noise=0.02, seed=7, client=client, device="cpu")
    assert report.n_ok == 6 and report.n_failed == 0
    drawn = []
    for p in inputs:
        lf = read_lightfield(p)
        for k in range(2):
            out = tmp_path / f"{p.stem}_{k:04d}.npz"
            want, cp = _serial(lambda: simulate_item(lf, p.name, k, path_kind="shake", extent=(1.0, 3.0),
                                                     infinity_disparity=0.5, noise=0.02, seed=7))
            assert np.array_equal(read_lightfield(out), want)
            np.testing.assert_array_equal(load_path_json(tmp_path / f"{p.stem}_{k:04d}.path.json"), cp)
            drawn.append(cp)
    # each item has a path of its own: the items of one input differ, and so do item k of different inputs
    assert all(not np.array_equal(a, b) for i, a in enumerate(drawn) for b in drawn[i + 1:])
    # without noise an item is simulate_blur by its path, exactly
    simulate_dataset(inputs[:1], tmp_path / "clean", seed=3, path_kind="linear", client=client, device="cpu")
    cp = load_path_json(tmp_path / "clean" / "scene0_0000.path.json")
    want = _serial(lambda: simulate_blur(read_lightfield(inputs[0]), cp))
    assert np.array_equal(read_lightfield(tmp_path / "clean" / "scene0_0000.npz"), want)
    rec = json.loads(_lines(tmp_path)[0])
    assert {"input", "output", "parameters", "seed", "item_seed", "version", "status", "time", "error",
            "size"} <= set(rec)
    assert "simulate_dataset" in (tmp_path / "README.md").read_text()


def test_item_seed_is_a_seed_sequence_of_the_run_seed_a_hash_of_the_name_and_the_index():
    import hashlib

    # item_seed's docstring and docs/batch.md: numpy's SeedSequence of the run's seed, a SHA-256 hash of the input's
    # name and the item's index, one 32-bit word of its state. Which word of the hash (its first 8 bytes, little-
    # endian) is pinned here too, so that a later version makes a dataset again bit for bit
    def documented(seed, name, index):
        digest = int.from_bytes(hashlib.sha256(name.encode("utf-8")).digest()[:8], "little")
        return int(np.random.SeedSequence([seed, digest, index]).generate_state(1, np.uint32)[0])

    cases = [(0, "a.npz", 0), (0, "a.npz", 1), (0, "b.npz", 0), (7, "scene0.npz", 3), (2**40, "views", 12)]
    for seed, name, index in cases:
        assert item_seed(seed, name, index) == documented(seed, name, index), (seed, name, index)
    # every item of every input is seeded apart
    assert len({item_seed(0, name, k) for name in ("a.npz", "b.npz", "c.npz") for k in range(4)}) == 12


def test_simulate_item_adds_gaussian_noise_of_the_stated_sigma_on_the_light_fields_scale():
    lf = np.full((3, 3, 32, 32), 0.5, np.float32)  # flat: the blur leaves it, the noise is all the difference
    out, _ = simulate_item(lf, "a", 0, noise=0.02)
    residual = out - 0.5
    assert abs(residual.std() / 0.02 - 1) < 0.05 and abs(residual.mean()) < 0.002
    # near white, the clipping to [0, 1] shows
    out, _ = simulate_item(np.full_like(lf, 0.99), "a", 0, noise=0.02)
    assert out.max() == 1.0 and 0.3 < (out == 1.0).mean() < 0.4  # P(N(0, 0.02) > 0.01) = 0.31
    # an integer light field (simulate_blur keeps its scale): noise and clipping on its range, 0..255
    out, _ = simulate_item(np.full(lf.shape, 128, np.uint8), "a", 0, noise=0.02)
    assert abs((out - 128).std() / (0.02 * 255) - 1) < 0.05 and 0 <= out.min() and out.max() <= 255


def test_draw_path_draws_sizes_and_directions_from_the_stated_ranges():
    from napari_lfdeblur.batch import draw_path
    from napari_lfdeblur.path import bezier_positions

    rng = np.random.default_rng(0)
    ends = np.array([np.diff(draw_path("linear", (1.0, 3.0), rng)[:, :2], axis=0)[0] for _ in range(60)])
    lengths, angles = np.hypot(*ends.T), np.degrees(np.arctan2(ends[:, 1], ends[:, 0])) % 360
    assert lengths.min() >= 1.0 and lengths.max() <= 3.0 and lengths.min() < 1.3 and lengths.max() > 2.7
    assert np.histogram(angles, bins=4, range=(0, 360))[0].min() >= 8  # every quadrant: a uniform angle
    for kind in ("linear", "arc"):  # a fixed extent is the length of these, exactly
        pos = bezier_positions(draw_path(kind, 2.0, rng), 2)
        assert np.isclose(np.linalg.norm(pos[-1, :2] - pos[0, :2]), 2.0)
    # shake, shake6 and random: control points in a box whose side is drawn from the range, so their spread in
    # (p_x, p_y) never passes the range's maximum and often passes its minimum (a box of side 1 cannot)
    for kind in ("shake", "shake6", "random"):
        spreads = np.array([np.ptp(draw_path(kind, (1.0, 3.0), rng)[:, :2], axis=0).max() for _ in range(60)])
        assert spreads.max() <= 3.0 and (spreads > 1.0).sum() >= 20, (kind, spreads.max(), (spreads > 1.0).sum())
    # arc: bowed by bend * length with the bend uniform in [-0.5, 0.5] (draw_path's docstring), to either side;
    # arc_path puts its middle control point 2 * bend * length across the chord from the chord's middle (a
    # quadratic Bezier reaches half way to it)
    bends = []
    for _ in range(60):
        cp = draw_path("arc", (1.0, 3.0), rng)[:, :2]
        chord, offset = cp[2] - cp[0], cp[1] - (cp[0] + cp[2]) / 2
        length = np.linalg.norm(chord)
        bends.append((chord[0] * offset[1] - chord[1] * offset[0]) / length / (2 * length))  # signed
    bends = np.array(bends)
    assert np.abs(bends).max() <= 0.5 and 15 <= (bends < 0).sum() <= 45, (bends.min(), bends.max())


def test_deblur_equals_the_serial_api_bit_for_bit(client, tmp_path):
    rng = np.random.default_rng(1)
    paths = [write_lightfield(tmp_path / f"b{i}.npz", rng.random((3, 3, 16, 16)).astype(np.float32))
             for i in range(2)]
    report = deblur_many(paths, tmp_path / "out", params=TINY, seed=5, client=client, device="cpu")
    assert report.n_ok == 2
    for p in paths:
        want = _serial(lambda: blind_deblur(read_lightfield(p), params=TINY, seed=item_seed(5, p.name, 0),
                                            device="cpu"))
        assert np.array_equal(read_lightfield(tmp_path / "out" / f"{p.stem}.npz"), want.lightfield)
        np.testing.assert_array_equal(load_path_json(tmp_path / "out" / f"{p.stem}.path.json"),
                                      want.control_points)
        # the evidence test's verdict, its reason and a rejected path come along
        rec = read_manifest(tmp_path / "out")[f"{p.stem}.npz"]
        assert rec["blur_found"] is want.info["blur_found"] and rec["restoration"] == want.info["restoration"]
        doc = json.loads((tmp_path / "out" / f"{p.stem}.path.json").read_text())
        assert doc["blur_evidence"] == want.info["message"] and doc["view_shape"] == [16, 16]
        assert doc["path_windows"] == [list(w) for w in want.info["windows"]]
        assert doc.get("final_weight") == want.info.get("final_weight")
        if "rejected_path" in want.info:
            np.testing.assert_array_equal(doc["rejected_control_points"], want.info["rejected_path"])
        else:
            assert "rejected_control_points" not in doc


def test_a_deblur_item_leaves_the_view_order_to_its_reader(tmp_path, recwarn):
    from _reference import moving_texture

    from napari_lfdeblur.batch._items import _deblur
    from napari_lfdeblur.epi import ViewOrderWarning

    lf = moving_texture(n_views=3, d=1.0, size=16).swapaxes(0, 1)  # views that look transposed
    spec = {"parameters": {"params": TINY.to_dict(), "infinity_disparity": 0.0}, "input": str(tmp_path / "a.npz"),
            "item_seed": 0}
    _deblur(lf, spec, "cpu", {})
    assert not [w for w in recwarn if issubclass(w.category, ViewOrderWarning)]  # the read of its file warned
    blind_deblur(lf, params=TINY, device="cpu")  # the same array given to the API is checked
    assert [w for w in recwarn if issubclass(w.category, ViewOrderWarning)]


def test_deblur_takes_each_inputs_stated_infinity_disparity(client, tmp_path):
    rng = np.random.default_rng(2)
    lf = rng.random((3, 3, 16, 16)).astype(np.float32)
    (tmp_path / "in").mkdir()
    write_lightfield(tmp_path / "in" / "half.npz", lf, metadata={"infinity_disparity": 0.5})  # as simulate's outputs
    write_lightfield(tmp_path / "in" / "plain.npz", lf)
    write_lightfield(tmp_path / "in" / "odd.npz", lf, metadata={"infinity_disparity": "far"})
    report = deblur_many(tmp_path / "in" / "*.npz", tmp_path / "out", params=TINY, client=client, device="cpu")
    assert (report.n_ok, report.n_failed) == (2, 1)
    for name, d_inf in (("half", 0.5), ("plain", 0.0)):
        assert json.loads((tmp_path / "out" / f"{name}.path.json").read_text())["infinity_disparity"] == d_inf
    want = _serial(lambda: blind_deblur(lf, params=TINY, infinity_disparity=0.5, device="cpu",
                                        seed=item_seed(0, "half.npz", 0)))
    assert np.array_equal(read_lightfield(tmp_path / "out" / "half.npz"), want.lightfield)
    # the parameters it ran with come back from the output file, as from any result's
    assert BlindParams.from_metadata(read_lightfield_with_metadata(tmp_path / "out" / "half.npz")[1]) == TINY
    rec = read_manifest(tmp_path / "out")["odd.npz"]
    assert rec["status"] == "failed" and "odd.npz states infinity_disparity = 'far'" in rec["error"]
    assert rec["error"].endswith("give infinity_disparity (--infinity-disparity on the command line)")  # the way out
    # so does `lfdeblur batch deblur` without --infinity-disparity (its help: default each input's own)
    (tmp_path / "tiny.json").write_text(TINY.to_json())
    assert main(["batch", "deblur", str(tmp_path / "in" / "half.npz"), str(tmp_path / "cli"), "--params",
                 str(tmp_path / "tiny.json"), "--scheduler", client.scheduler.address, "--device", "cpu"]) == 0
    assert json.loads((tmp_path / "cli" / "half.path.json").read_text())["infinity_disparity"] == 0.5
    assert np.array_equal(read_lightfield(tmp_path / "cli" / "half.npz"), want.lightfield)
    # given, it is every item's
    deblur_many(tmp_path / "in" / "half.npz", tmp_path / "given", params=TINY, infinity_disparity=0.0,
                client=client, device="cpu")
    assert json.loads((tmp_path / "given" / "half.path.json").read_text())["infinity_disparity"] == 0.0


def test_bad_items_are_recorded_and_the_others_complete(client, inputs, tmp_path, capsys):
    bad = tmp_path / "in"
    bad.mkdir()
    (bad / "corrupt.npz").write_bytes(b"not a zip file")
    nan = np.full((3, 3, 8, 8), np.nan, dtype=np.float32)
    np.save(bad / "nan.npy", nan)
    files = [*inputs, bad / "corrupt.npz", bad / "nan.npy"]
    report = simulate_dataset(files, tmp_path / "out", client=client, device="cpu")
    assert report.n_ok == 3 and report.n_failed == 2
    last = read_manifest(tmp_path / "out")
    assert "corrupt_0000.npz" in last and "not a readable" in last["corrupt_0000.npz"]["error"]
    assert last["nan_0000.npz"]["status"] == "failed" and "NaN" in last["nan_0000.npz"]["error"]
    assert not (tmp_path / "out" / "corrupt_0000.npz").exists()
    # the CLI says how many failed, with exit status 1; bad usage is 2
    argv = ["batch", "simulate", str(bad / "*"), str(tmp_path / "cli"), "--scheduler", client.scheduler.address,
            "--device", "cpu"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "2 of 2 items failed" in err and "corrupt.npz" in err and "dashboard" in err
    # some items failed and others are done: exit status 1 as well (docs/batch.md: 1 when some failed)
    write_lightfield(bad / "good.npz", read_lightfield(inputs[0]))
    assert main(argv) == 1
    assert "2 of 3 items failed (1 done, 0 already done" in capsys.readouterr().err
    assert main(["batch", "simulate", str(tmp_path / "none*.npz"), str(tmp_path / "cli")]) == 2


def test_a_rerun_skips_finished_items_and_redoes_the_others(client, inputs, tmp_path):
    out = tmp_path / "out"
    assert simulate_dataset(inputs, out, n_per_input=2, client=client, device="cpu").n_ok == 6
    again = simulate_dataset(inputs, out, n_per_input=2, client=client, device="cpu")
    assert (again.n_ok, again.n_skipped) == (0, 6) and len(_lines(out)) == 6  # no work done
    (out / "scene1_0001.npz").unlink()
    before = read_lightfield(out / "scene2_0000.npz")
    data = (out / "scene2_0000.npz").read_bytes()
    (out / "scene2_0000.npz").write_bytes(data[: len(data) // 2])  # cut short: redone
    write_lightfield(out / "scene0_0000.npz", np.zeros((2, 2, 4, 4)), overwrite=True)  # someone else's file
    third = simulate_dataset(inputs, out, n_per_input=2, client=client, device="cpu")
    assert (third.n_skipped, third.n_ok, third.n_failed) == (3, 2, 1)
    assert "pass overwrite" in third.failed[0]["error"] and read_lightfield(out / "scene0_0000.npz").shape[0] == 2
    assert np.array_equal(read_lightfield(out / "scene2_0000.npz"), before)
    fourth = simulate_dataset(inputs, out, n_per_input=2, client=client, device="cpu", overwrite=True)
    assert fourth.n_ok == 6
    # an item whose path file was lost since is redone (not refused as 'not this item's output')
    (out / "scene1_0000.path.json").unlink()
    fifth = simulate_dataset(inputs, out, n_per_input=2, client=client, device="cpu")
    assert (fifth.n_ok, fifth.n_skipped, fifth.n_failed) == (1, 5, 0) and (out / "scene1_0000.path.json").is_file()
    # other parameters into the same folder: existing outputs are never replaced without overwrite, and the
    # dataset card keeps describing what the folder holds (it took the failed run's command)
    card = (out / "README.md").read_text()
    changed = simulate_dataset(inputs, out, n_per_input=1, noise=0.1, client=client, device="cpu")
    assert changed.n_failed == 3 and changed.n_ok == 0
    assert (out / "README.md").read_text() == card


def test_a_killed_run_leaves_no_corrupt_file_and_a_rerun_completes_it(client, tmp_path):
    rng = np.random.default_rng(2)
    paths = [write_lightfield(tmp_path / f"k{i}.npz", rng.random((3, 3, 16, 16)).astype(np.float32))
             for i in range(4)]
    out = tmp_path / "out"
    restarted = threading.Event()

    def restart_on_first(rec):  # kill every worker while the other items run
        if not restarted.is_set():
            restarted.set()
            client.restart()

    first = deblur_many(paths, out, params=TINY, client=client, device="cpu", callback=restart_on_first)
    assert restarted.is_set() and first.n_ok + first.n_failed == 4 and first.n_failed >= 1
    assert all("cancelled" in r["error"] for r in first.failed)  # recorded, not lost
    # what a kill at any other moment can leave: a writer's temporary file, an orphan path JSON,
    # a manifest line cut short, an output written but not yet recorded
    (out / ".k3.npz.tmp123-abcd.npz").write_bytes(b"partial")
    (out / "k3.path.json").write_text(json.dumps({"control_points": [[0, 0, 0], [1, 0, 0]], "lightfield": "k3.npz"}))
    with open(out / "manifest.jsonl", "a") as fh:
        fh.write('{"output": "k0.npz", "stat')
    second = deblur_many(paths, out, params=TINY, client=client, device="cpu")
    assert second.n_failed == 0 and second.n_ok + second.n_skipped == 4
    assert _leftovers(out) == []
    for p in paths:
        want = _serial(lambda: blind_deblur(read_lightfield(p), params=TINY, seed=item_seed(0, p.name, 0),
                                            device="cpu"))
        assert np.array_equal(read_lightfield(out / p.name), want.lightfield)
    last = read_manifest(out)
    assert all(last[p.name]["status"] == "ok" for p in paths)
    # an output on disk whose manifest line was lost is recognised as this item's, not recomputed or refused
    lines = [ln for ln in _lines(out) if '"k1.npz"' not in ln]
    (out / "manifest.jsonl").write_text("\n".join(lines) + "\n")
    third = deblur_many(paths, out, params=TINY, client=client, device="cpu")
    assert third.n_skipped == 3 and third.n_ok == 1 and read_manifest(out)["k1.npz"]["recovered"] is True
    # with the verdict its file states (lfdeblur info counts it)
    assert read_manifest(out)["k1.npz"]["blur_found"] == last["k1.npz"]["blur_found"]
    assert read_manifest(out)["k1.npz"]["restoration"] == last["k1.npz"]["restoration"]


def test_cli_batch_deblur_with_params(client, tmp_path, capsys):
    rng = np.random.default_rng(3)
    (tmp_path / "in").mkdir()
    write_lightfield(tmp_path / "in" / "c0.npz", rng.random((3, 3, 16, 16)).astype(np.float32))
    (tmp_path / "tiny.json").write_text(TINY.to_json())
    argv = ["batch", "deblur", str(tmp_path / "in" / "*.npz"), str(tmp_path / "out"), "--params",
            str(tmp_path / "tiny.json"), "--scheduler", client.scheduler.address, "--device", "cpu"]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    rec = read_manifest(tmp_path / "out")["c0.npz"]
    assert "all 1 items" in printed and rec["status"] == "ok"
    # the count of inputs returned unchanged is said when there are any (16 px views are too small to split
    # for the agreement check of a light restoration: with little blur found, the input comes back)
    assert ("1 with little blur found, returned unchanged" in printed) is (rec["blur_found"] is False)
    assert rec["restoration"] == ("full" if rec["blur_found"] else "none")
    assert "lfdeblur batch deblur" in (tmp_path / "out" / "README.md").read_text()
    assert main(argv) == 0 and "1 already done" in capsys.readouterr().out


def test_cli_batch_simulate_draws_the_extent_from_a_min_max_range(client, inputs, tmp_path):
    out = tmp_path / "out"
    # docs/batch.md's own example: --extent 0.5:3, a length drawn from [0.5, 3] for linear paths
    assert main(["batch", "simulate", str(inputs[0]), str(out), "--path-kind", "linear", "--extent", "0.5:3",
                 "--n-per-input", "6", "--n-times", "4", "--scheduler", client.scheduler.address,
                 "--device", "cpu"]) == 0
    last = read_manifest(out)
    assert len(last) == 6 and all(rec["parameters"]["extent"] == [0.5, 3.0] for rec in last.values())
    for k in range(6):
        cp = load_path_json(out / f"scene0_{k:04d}.path.json")
        assert 0.5 <= np.linalg.norm(cp[-1, :2] - cp[0, :2]) <= 3.0


def test_the_dataset_cards_command_makes_the_same_dataset_again(client, inputs, tmp_path):
    import shlex

    first, again = tmp_path / "first", tmp_path / "again"
    where = ["--scheduler", client.scheduler.address, "--device", "cpu"]  # not data options: not in the card
    assert main(["batch", "simulate", str(inputs[0]), str(first), "--n-per-input", "2", "--path-kind", "shake",
                 "--extent", "0.5:2", "--noise", "0.01", "--n-times", "4", "--seed", "3", *where]) == 0
    card = (first / "README.md").read_text()
    command = shlex.split(card.split("```bash\n")[1].split("\n```")[0])
    assert command[:3] == ["lfdeblur", "batch", "simulate"] and str(first) in command
    # the card's command, into another folder, makes the same items bit for bit
    assert main([str(again) if word == str(first) else word for word in command[1:]] + where) == 0
    names = sorted(p.name for p in first.glob("*.npz"))
    assert names == ["scene0_0000.npz", "scene0_0001.npz"] and sorted(p.name for p in again.glob("*.npz")) == names
    for name in names:
        assert np.array_equal(read_lightfield(again / name), read_lightfield(first / name)), name


def test_value_range_reads_the_inputs_and_is_part_of_the_items_parameters(client, tmp_path, capsys):
    rng = np.random.default_rng(4)
    lf = rng.random((3, 3, 8, 8)).astype(np.float32)
    (tmp_path / "in").mkdir()
    np.save(tmp_path / "in" / "raw.npy", lf * 4095.0)  # floats on a 12-bit scale: unreadable without a range
    report = simulate_dataset(tmp_path / "in" / "raw.npy", tmp_path / "plain", path_kind="linear", client=client,
                              device="cpu")
    assert report.n_failed == 1 and "--value-range" in report.records[0]["error"]
    report = simulate_dataset(tmp_path / "in" / "raw.npy", tmp_path / "sim", path_kind="linear",
                              value_range=(0, 4095), client=client, device="cpu")
    assert report.n_ok == 1 and report.records[0]["parameters"]["value_range"] == [0.0, 4095.0]
    cp = load_path_json(tmp_path / "sim" / "raw_0000.path.json")
    want = _serial(lambda: simulate_blur(read_lightfield(tmp_path / "in" / "raw.npy", value_range=(0, 4095)), cp))
    assert np.array_equal(read_lightfield(tmp_path / "sim" / "raw_0000.npz"), want)
    with pytest.raises(ValueError, match="lo < hi"):
        deblur_many(tmp_path / "in" / "raw.npy", tmp_path / "bad", value_range=(1, 0), client=client)
    argv = ["batch", "deblur", str(tmp_path / "in" / "raw.npy"), str(tmp_path / "out"), "--value-range", "auto",
            "--scheduler", client.scheduler.address, "--device", "cpu", "--params", str(tmp_path / "tiny.json")]
    (tmp_path / "tiny.json").write_text(TINY.to_json())
    assert main(argv) == 0
    rec = read_manifest(tmp_path / "out")["raw.npz"]
    assert rec["status"] == "ok" and rec["parameters"]["value_range"] == "auto"
    assert "--value-range=auto" in (tmp_path / "out" / "README.md").read_text()
    want = _serial(lambda: blind_deblur(read_lightfield(tmp_path / "in" / "raw.npy", value_range="auto"),
                                        params=TINY, seed=item_seed(0, "raw.npy", 0), device="cpu"))
    assert np.array_equal(read_lightfield(tmp_path / "out" / "raw.npz"), want.lightfield)


def test_batch_summary_counts_inputs_returned_unchanged_and_restored_lightly():
    recs = [{"status": "ok", "blur_found": False, "restoration": r} for r in ("none", "light", "light")]
    recs += [{"status": "ok", "blur_found": True, "restoration": "full"}, {"status": "failed"}]
    assert weak_blur_summary(recs) == ("; 1 with little blur found, returned unchanged (blur_found in the manifest)"
                                       "; 2 with little blur found, restored lightly (restoration in the manifest)")
    assert weak_blur_summary(recs[3:]) == ""
    refused = [{"status": "ok", "blur_found": True, "restoration": "none"}]
    assert weak_blur_summary(recs[3:] + refused) == ("; 1 with blur found but a restoration that did not reproduce "
                                                     "the data, returned unchanged (restoration in the manifest)")


def test_embedded_cluster_workers_start_with_malloc_thresholds_no_profiler_and_slow_timers(monkeypatch):
    # glibc reads MALLOC_MMAP_THRESHOLD_ once, at process start: it must be in the worker's environment
    # from the spawn on, not set afterwards by the nanny
    from napari_lfdeblur.batch import connect
    WORKER_MMAP_THRESHOLD = 32 * 2**20

    def environ_at_start():
        with open(f"/proc/{os.getpid()}/environ", "rb") as f:
            start = dict(kv.split(b"=", 1) for kv in f.read().split(b"\0") if b"=" in kv)
        return tuple(start.get(k, b"").decode() for k in (b"MALLOC_MMAP_THRESHOLD_", b"MALLOC_TRIM_THRESHOLD_"))

    if not Path("/proc/self/environ").exists():
        pytest.skip("needs /proc (Linux)")
    # dask lets this process's environment override its settings, and a nanny puts its own values
    # there when it spawns a worker: clear what the module's other cluster left
    for name in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_"):
        monkeypatch.delenv(name, raising=False)
    def profiling():
        import dask

        return (dask.config.get("distributed.worker.profile.enabled"),
                dask.config.get("distributed.admin.tick.interval"))

    with connect(workers=1, device="cpu") as c:
        found = c.run(environ_at_start)
        profiled = c.run(profiling)
    # the trim threshold replaces the nanny's 64 KiB: glibc's dynamic rule, twice the mmap threshold
    assert list(found.values()) == [(str(WORKER_MMAP_THRESHOLD), str(2 * WORKER_MMAP_THRESHOLD))]
    assert list(profiled.values()) == [(False, "500ms")]  # the timers' settings reach the worker process


def test_embedded_cluster_workers_log_a_lost_connection_on_one_line():
    # on Ctrl-C the scheduler can close before a worker, whose heartbeat then logs the lost connection with
    # exc_info: the CLI must print no traceback, so the worker's own handlers fold it into one line
    import logging

    from napari_lfdeblur.batch import connect

    def heartbeat_failure():
        try:
            raise OSError("Stream is closed")
        except OSError:
            record = logging.getLogger("distributed.worker").makeRecord(
                "distributed.worker", logging.ERROR, __file__, 1, "Failed to communicate with scheduler", None,
                sys.exc_info())
        handlers = logging.getLogger("distributed").handlers
        return [h.format(record) for h in handlers if h.filter(record)]

    with connect(workers=1, device="cpu") as c:
        (lines,) = c.run(heartbeat_failure).values()
    assert len(lines) >= 1
    for line in lines:
        assert "Traceback" not in line and "\n" not in line, line
        assert line.endswith("Failed to communicate with scheduler OSError: Stream is closed"), line


def test_a_ctrl_c_that_lands_in_a_finalizer_still_stops_the_run():
    # Python reports an exception raised in __del__ as "ignored" and goes on: a Ctrl-C that lands while a
    # dask Future is released would be lost, and the batch run would go to its end
    import time

    from napari_lfdeblur._cli_batch import ctrl_c_never_swallowed

    class Releasing:
        def __del__(self):
            raise KeyboardInterrupt

    default = sys.unraisablehook
    # Python's own Ctrl-C handler, which a process started in the background (SIGINT ignored) lacks
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt), ctrl_c_never_swallowed():
            obj = Releasing()
            del obj  # the finalizer's KeyboardInterrupt is raised again in the main thread, 0.1 s after
            for _ in range(100):
                time.sleep(0.01)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert sys.unraisablehook is default


def test_shake6_items_are_6dof_and_blurred_by_their_path():
    from napari_lfdeblur.batch._items import draw_path

    cp = draw_path("shake6", (1.0, 2.0), np.random.default_rng(0))
    assert cp.shape == (5, 6) and 0 < np.abs(cp[:, 3:]).max() <= 0.005
    lf = np.random.default_rng(1).random((3, 3, 16, 16)).astype(np.float32)
    blurred, cp = simulate_item(lf, "a", 0, path_kind="shake6", extent=1.5, seed=4, n_times=8)
    assert cp.shape[1] == 6
    np.testing.assert_array_equal(blurred, simulate_blur(lf, cp, n_times=8, device="cpu"))


def test_a_pattern_takes_the_light_fields_it_matches_and_names_the_rest(tmp_path):
    """'out/*' over a batch's output folder: its light fields, not its path files, manifest and README."""
    from napari_lfdeblur.batch import expand_inputs

    lf = np.zeros((2, 2, 4, 4), np.float32)
    write_lightfield(tmp_path / "a.npz", lf, control_points=[[0, 0, 0], [1, 0, 0]])  # + a.path.json
    write_lightfield(tmp_path / "views", lf)  # a folder of views
    (tmp_path / "manifest.jsonl").write_text("{}\n")
    (tmp_path / "README.md").write_text("notes")
    with pytest.warns(UserWarning, match=r"skipped 3 match\(es\) that are not light fields: README.md, "
                                         r"a.path.json, manifest.jsonl"):
        assert expand_inputs(str(tmp_path / "*")) == [tmp_path / "a.npz", tmp_path / "views"]
    with pytest.raises(ValueError, match=r"no light field matches .*\(it matches 1 other file\(s\), such as a.path"):
        expand_inputs(str(tmp_path / "*.json"))
    # given one by one, each must be there and of a kind the reader knows (its content is read by its item)
    listed = [tmp_path / "views", tmp_path / "a.npz"]
    assert expand_inputs(listed) == listed
    with pytest.raises(ValueError, match="input .*README.md is not a light field the reader knows$"):
        expand_inputs([tmp_path / "README.md", tmp_path / "a.npz"])
    with pytest.raises(FileNotFoundError, match="input .*late.npz does not exist"):
        expand_inputs(str(tmp_path / "late.npz"))  # was an item named 'late.npz_0000.npz' that failed
    (tmp_path / "scenes").mkdir()
    write_lightfield(tmp_path / "scenes" / "s.npz", lf)
    with pytest.raises(ValueError, match=r"scenes is not a light field the reader knows; for the files in it pass "
                                         r"a pattern such as '.*scenes/\*'"):
        expand_inputs(tmp_path / "scenes")


def test_a_script_without_a_main_guard_gets_told_why_the_workers_failed(tmp_path):
    import subprocess

    write_lightfield(tmp_path / "scene.npz", np.random.default_rng(0).random((3, 3, 8, 8)).astype(np.float32))
    script = tmp_path / "unguarded.py"
    script.write_text("from napari_lfdeblur.batch import simulate_dataset\n"
                      "simulate_dataset('scene.npz', 'out', seed=1, workers=1, device='cpu')\n")
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode != 0
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith("RuntimeError: the embedded cluster's workers did not start")
    assert "if __name__ == '__main__':" in last
    # the worker refused before touching the output folder: no 'another run is writing' (its manifest's lock)
    assert "another run is writing" not in run.stderr
    guarded = tmp_path / "guarded.py"
    guarded.write_text("from napari_lfdeblur.batch import simulate_dataset\n"
                       "if __name__ == '__main__':\n"
                       "    print(simulate_dataset('scene.npz', 'out', seed=1, workers=1, device='cpu').n_ok)\n")
    run = subprocess.run([sys.executable, str(guarded)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split()[-1] == "1"


@pytest.mark.parametrize("kwargs, error, message", [
    ({"noise": -1.0}, ValueError, "noise must be >= 0"),
    ({"n_times": 0}, ValueError, "n_times must be >= 2"),
    ({"n_times": 2.5}, TypeError, "n_times must be an integer"),
    ({"infinity_disparity": float("nan")}, ValueError, "infinity_disparity must be finite"),
    ({"device": "cuda"}, ValueError, "no CUDA GPU"),
    ({"workers": 0}, ValueError, "workers must be an integer >= 1"),
    ({"client": 42}, TypeError, "client must be a distributed.Client"),
])
def test_bad_arguments_fail_before_the_run_starts(inputs, tmp_path, kwargs, error, message):
    import torch

    if kwargs.get("device") == "cuda" and torch.cuda.is_available():
        pytest.skip("a GPU is there")
    out = tmp_path / "out"
    with pytest.raises(error, match=message):
        simulate_dataset(inputs, out, **kwargs)
    assert not out.exists()  # no cluster started, no manifest written
    if not {"device", "noise", "n_times"} & set(kwargs):
        with pytest.raises(error, match=message):
            deblur_many(inputs, out, **kwargs)
        assert not out.exists()


def test_outputs_state_their_blur_and_other_files_are_never_replaced(client, inputs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "scene0_0000.path.json").write_text('{"my": "precious path"}')  # a file of the user's, of an item's name
    np.savez(out / "scene1_0000.npz", weights=np.ones(3))  # not a light field
    users = {name: (out / name).read_bytes() for name in ("scene0_0000.path.json", "scene1_0000.npz")}
    report = simulate_dataset(inputs, out, infinity_disparity=1.0, n_times=8, client=client, device="cpu")
    assert (report.n_ok, report.n_failed) == (1, 2)
    assert all("is not this item's" in r["error"] and "--overwrite" in r["error"] for r in report.failed)
    assert (out / "scene0_0000.path.json").read_text() == '{"my": "precious path"}'
    assert list(np.load(out / "scene1_0000.npz")) == ["weights"]
    # the same call again (what the command's failure message says to do): a failed record is not an output of
    # this item, so the user's files are refused again and left as they are
    again = simulate_dataset(inputs, out, infinity_disparity=1.0, n_times=8, client=client, device="cpu")
    assert (again.n_ok, again.n_skipped, again.n_failed) == (0, 1, 2)
    assert all("is not this item's" in r["error"] for r in again.failed)
    assert {name: (out / name).read_bytes() for name in users} == users
    # the output says what it was blurred with, so that deblurring it takes its infinity disparity
    meta = read_lightfield_with_metadata(out / "scene2_0000.npz")[1]
    assert (meta["infinity_disparity"], meta["n_times"]) == (1.0, 8)
    cp = load_path_json(out / "scene2_0000.path.json")  # and it was blurred with what it states
    want = _serial(lambda: simulate_blur(read_lightfield(inputs[2]), cp, n_times=8, infinity_disparity=1.0))
    assert np.array_equal(read_lightfield(out / "scene2_0000.npz"), want)
    assert json.loads((out / "scene2_0000.path.json").read_text())["lightfield"] == "scene2_0000.npz"
    deblur_many(out / "scene2_0000.npz", tmp_path / "deblurred", params=TINY, client=client, device="cpu")
    assert json.loads((tmp_path / "deblurred" / "scene2_0000.path.json").read_text())["infinity_disparity"] == 1.0


def test_cli_batch_refuses_before_it_starts(inputs, tmp_path, capsys):
    import torch

    out = tmp_path / "o"
    (tmp_path / "in").mkdir()
    write_lightfield(tmp_path / "in" / "a.npz", read_lightfield(inputs[0]))
    (tmp_path / "in" / "notes.txt").write_text("not a light field")
    pattern = str(tmp_path / "in" / "*")
    if not torch.cuda.is_available():  # the embedded cluster would run here: refused up front, no folder made
        assert main(["batch", "simulate", pattern, str(out), "--device", "cuda"]) == 2
        err = capsys.readouterr().err
        assert "no CUDA GPU" in err and not out.exists()
        assert err.count("skipped 1 match(es) that are not light fields: notes.txt") == 1  # said once
    assert main(["batch", "simulate", str(inputs[0]), str(out), "--n-per-input", "0"]) == 2
    assert "--n-per-input must be >= 1; got 0" in capsys.readouterr().err and not out.exists()
    assert main(["batch", "deblur", pattern, str(tmp_path / "in")]) == 2  # into the inputs' own folder
    assert "would replace it: choose another output folder" in capsys.readouterr().err


def test_a_run_refused_for_its_device_leaves_the_dataset_card(client, inputs, tmp_path):
    from napari_lfdeblur.batch._run import CARD

    out = tmp_path / "ds"
    simulate_dataset(inputs[:1], out, client=client, device="cpu", n_times=4, seed=0)
    card = (out / CARD).read_text()
    # no worker offers a GPU: refused before any item, and the card still describes the items there
    with pytest.raises(ValueError, match="no worker offers the resource GPU"):
        simulate_dataset(inputs[:1], out, client=client, device="cuda", n_times=8, seed=5)
    assert (out / CARD).read_text() == card
    with pytest.raises(ValueError, match="no worker offers the resource GPU"):
        simulate_dataset(inputs[:1], tmp_path / "new", client=client, device="cuda")
    assert not (tmp_path / "new" / CARD).exists()


def test_a_deblurred_item_records_the_device_it_ran_on(monkeypatch, inputs, tmp_path):
    from napari_lfdeblur import blind
    from napari_lfdeblur.batch import _items

    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)  # asked for the GPU, which fell back to the CPU

    def fell_back(lf, **kwargs):
        assert str(kwargs["device"]) == "cuda"
        return blind.BlindResult(np.asarray(lf, np.float32), np.zeros((4, 3)), info={"device": "cpu"})

    monkeypatch.setattr(blind, "blind_deblur", fell_back)
    from napari_lfdeblur.batch._run import make_spec

    spec = make_spec("deblur", inputs[0], 0, tmp_path / "a.npz", parameters={"params": json.loads(TINY.to_json()),
                     "infinity_disparity": 0.0}, seed=0, overwrite=False, version="test")
    spec["device"] = "cuda"
    n = torch.get_num_threads()
    try:
        rec = _items.run_item(spec)
    finally:
        torch.set_num_threads(n)  # a worker's setting
    assert rec["status"] == "ok", rec.get("error")
    assert rec["device"] == "cpu"  # where it ran, not what was asked for


def test_an_output_may_not_replace_its_inputs_path_file(tmp_path):
    from napari_lfdeblur.io import write_lightfield as write

    src = write(tmp_path / "a.npy", np.random.default_rng(0).random((3, 3, 8, 8)).astype(np.float32),
                control_points=[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])  # a.npy and its a.path.json
    path_file = tmp_path / "a.path.json"
    kept = path_file.read_bytes()
    # deblurred into the same folder, a.npz would write its path to a.path.json, the input's
    with pytest.raises(ValueError, match="would replace its path file"):
        deblur_many([src], tmp_path, params=TINY, device="cpu", overwrite=True)
    assert path_file.read_bytes() == kept and not (tmp_path / "a.npz").exists()


@pytest.mark.filterwarnings("ignore:Port .* is already in use")  # the module's cluster holds distributed's port
def test_items_on_one_workers_threads_keep_their_own_warnings_and_leave_the_process_as_it_was(tmp_path):
    """A worker may run several items at once on its threads: each record lists the warnings its own item raised
    (a light field whose view axes are swapped warns when read); the warnings machinery and torch's thread count
    are as before once the batch is over (an in-process cluster shares them with the caller)."""
    import warnings

    import torch

    from napari_lfdeblur import synthetic_scene

    (tmp_path / "in").mkdir()
    lf, _ = synthetic_scene((5, 5, 24, 24), seed=0)
    write_lightfield(tmp_path / "in" / "a_swapped.npz", np.ascontiguousarray(lf.transpose(1, 0, 2, 3)))
    for i in range(3):
        write_lightfield(tmp_path / "in" / f"ok{i}.npz", synthetic_scene((5, 5, 24, 24), seed=i + 1)[0])
    show, filters, n_threads = warnings.showwarning, list(warnings.filters), torch.get_num_threads()
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=4, dashboard_address=None) as client:
        report = simulate_dataset(str(tmp_path / "in" / "*.npz"), tmp_path / "out", n_per_input=2, n_times=4,
                                  client=client, device="cpu")
    assert report.n_ok == 8
    for name, rec in read_manifest(tmp_path / "out").items():
        swapped = any("ViewOrderWarning" in w for w in rec["warnings"])
        assert swapped is name.startswith("a_swapped"), (name, rec["warnings"])
    # (the cluster's own imports may add filters for their warnings; none for every warning is left)
    assert warnings.showwarning is show and torch.get_num_threads() == n_threads
    assert [f for f in warnings.filters if f not in filters and f[2] is Warning] == []
