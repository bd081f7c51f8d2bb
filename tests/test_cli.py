"""The lfdeblur command: simulate, demo and error handling."""

import json

import numpy as np
import pytest

import napari_lfdeblur
from napari_lfdeblur import read_lightfield, read_lightfield_with_metadata, simulate_blur, write_lightfield
from napari_lfdeblur.blind import BlindParams
from napari_lfdeblur.cli import main
from napari_lfdeblur.path import linear_path, load_path_json, preset_path, save_path_json


@pytest.fixture
def lf_file(tmp_path):
    lf = np.random.default_rng(0).random((5, 5, 12, 12)).astype(np.float32)
    np.save(tmp_path / "lf.npy", lf)
    return lf, tmp_path / "lf.npy"


def test_simulate_with_preset(lf_file, tmp_path):
    lf, src = lf_file
    out = tmp_path / "blurred.npz"
    assert main(["simulate", str(src), str(out), "--path", "linear:2", "--n-times", "8"]) == 0
    np.testing.assert_allclose(read_lightfield(out), simulate_blur(lf, linear_path(2.0), n_times=8), atol=1e-6)


def test_every_reading_command_reads_a_mosaic_of_views(lf_file, tmp_path, capsys):
    lf, _ = lf_file
    mosaic = write_lightfield(tmp_path / "m.png", lf, layout="mosaic", bit_depth=16)
    sharp = read_lightfield(mosaic, layout="mosaic", grid=(5, 5))
    out = tmp_path / "b.npz"
    assert main(["simulate", str(mosaic), str(out), "--path", "linear:2", "--n-times", "8",
                 "--layout", "mosaic", "--grid", "5,5"]) == 0
    np.testing.assert_allclose(read_lightfield(out), simulate_blur(sharp, linear_path(2.0), n_times=8), atol=1e-6)
    capsys.readouterr()
    with pytest.raises(SystemExit) as stop:  # argparse's one-line error
        main(["deconvolve", str(mosaic), str(tmp_path / "d.npz"), "--layout", "mosaic", "--grid", "5"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "--grid: '5': expected V,U" in err and not (tmp_path / "d.npz").exists()


def test_simulate_with_json_path_and_no_overwrite(lf_file, tmp_path, capsys):
    lf, src = lf_file
    cp = np.array([[0.3, -0.2, 0.1], [-0.5, 0.4, -0.2], [0.8, 0.1, 0.0]])
    save_path_json(tmp_path / "path.json", cp)
    out = tmp_path / "b.npz"
    args = ["simulate", str(src), str(out), "--path", str(tmp_path / "path.json"), "--infinity-disparity", "0.5"]
    assert main(args) == 0
    np.testing.assert_allclose(
        read_lightfield(out), simulate_blur(lf, cp, n_times=32, infinity_disparity=0.5), atol=1e-6
    )
    before = out.read_bytes()
    assert main(args) == 2  # exists: refused, file untouched
    assert "exists" in capsys.readouterr().err
    assert out.read_bytes() == before
    # an output that is the input is refused, --overwrite or not (simulate and deconvolve alike)
    kept = src.read_bytes()
    assert main(["simulate", str(src), str(src), "--path", str(tmp_path / "path.json"), "--overwrite"]) == 2
    assert "is the input; an output may not replace it" in capsys.readouterr().err
    assert main(["deconvolve", str(out), str(tmp_path / "path.json"), str(out), "--overwrite"]) == 2
    assert "is the input" in capsys.readouterr().err and src.read_bytes() == kept and out.read_bytes() == before
    # the --path file is an input too: an output whose path file it would be is refused
    save_path_json(tmp_path / "c.path.json", cp, n_times=9, note="my own notes")
    stated = (tmp_path / "c.path.json").read_bytes()
    assert main(["simulate", str(src), str(tmp_path / "c.npy"), "--path", str(tmp_path / "c.path.json"),
                 "--overwrite"]) == 2
    assert "c.path.json is the input" in capsys.readouterr().err
    assert (tmp_path / "c.path.json").read_bytes() == stated and not (tmp_path / "c.npy").exists()


def test_a_path_for_views_of_another_size_is_warned_about(lf_file, tmp_path, capsys):
    lf, src = lf_file
    cp = np.array([[0.3, -0.2, 0.4], [-0.5, 0.4, -0.3]])  # with p_z: its blur depends on the views' size
    save_path_json(tmp_path / "other.json", cp, view_shape=[20, 12])
    save_path_json(tmp_path / "own.json", cp, view_shape=[12, 12])
    (tmp_path / "odd.json").write_text(json.dumps({"control_points": cp.tolist(), "view_shape": "big"}))
    for name, said in (("other", "the path is for 20x12 views and these are 12x12"), ("own", None),
                       ("odd", "view_shape = 'big', which is not two whole numbers")):
        out = tmp_path / f"b_{name}.npz"
        assert main(["simulate", str(src), str(out), "--path", str(tmp_path / f"{name}.json"), "--n-times", "6"]) == 0
        err = capsys.readouterr().err
        assert ("warning" in err) is bool(said) and (said is None or said in err)
        np.testing.assert_allclose(read_lightfield(out), simulate_blur(lf, cp, n_times=6), atol=1e-6)  # it ran
    # the blurred file's own path is for its views: no warning; the other file's is
    args = ["--iterations", "2", "--device", "cpu"]
    assert main(["deconvolve", str(tmp_path / "b_own.npz"), str(tmp_path / "d1.npz"), *args]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main(["deconvolve", str(tmp_path / "b_own.npz"), str(tmp_path / "other.json"), str(tmp_path / "d2.npz"),
                 *args]) == 0
    err = capsys.readouterr().err
    said = f"lfdeblur deconvolve: warning: {tmp_path / 'other.json'}: the path is for 20x12 views and these are 12x12"
    assert said in err
    assert "path_in_window" in err and (tmp_path / "d2.npz").exists()
    # an input cropped by another program, its path file kept: said once (by the reader), and it runs
    np.save(tmp_path / "c.npy", read_lightfield(tmp_path / "b_own.npz")[:, :, 2:])
    (tmp_path / "c.path.json").write_text((tmp_path / "b_own.path.json").read_text())
    assert main(["deconvolve", str(tmp_path / "c.npy"), str(tmp_path / "d3.npz"), *args]) == 0
    assert capsys.readouterr().err.count("the path is for 12x12 views and these are 10x12") == 1


@pytest.mark.parametrize(
    "args, message",
    [
        (["simulate", "missing.npy", "o.npz", "--path", "linear"], "does not exist"),
        (["simulate", "{src}", "o.npz", "--path", "zigzag"], "neither a JSON file nor a preset"),
        (["simulate", "{src}", "o.npz", "--path", "linear", "--n-times", "1"], "n_times"),
        (["simulate", "{src}", "o.npz", "--path", "nothere.json"], "does not exist"),
        (["simulate", "{src}", "o.npz", "--path", "shake:1:0:0.01"], "only shake6 takes a ROTATION"),
        (["simulate", "{src}", "o.npz", "--path", "shake6:1:0:0.5"], "rotation must be in [0, 0.2]"),
        (["simulate", "{src}", "o.npz", "--path", "linear:3:7"], "linear is not random and takes no SEED"),
        (["simulate", "{src}", "no/o.npz", "--path", "linear"], "the folder no does not exist"),
        (["simulate", "{src}", "o.gif", "--path", "linear"], "cannot tell the format"),
        (["deblur", "{src}", "o.npz", "--preset", "paper", "--motion", "6dof"], "needs method='alternating'"),
    ],
)
def test_cli_errors_are_one_line(args, message, lf_file, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _, src = lf_file
    code = main([a.format(src=src) for a in args])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.startswith(f"lfdeblur {args[0]}: error: ") and err.count("\n") == 1, err
    assert not (tmp_path / "o.npz").exists()


def test_demo_quick(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--quick", "--skip-blind"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    from napari_lfdeblur import demo

    samples, c = demo._samples(True), summary["psnr_crop"]
    for name in ("synthetic", "lytro"):
        rec = summary["samples"][name]
        sharp = samples[name][0]
        assert (out / f"{name}.png").stat().st_size > 10_000
        # the written blurred light field is the sharp one blurred along the true path, plus noise of the stated std
        blurred = read_lightfield(out / f"{name}_blurred.npz")
        assert list(blurred.shape) == rec["shape"] == list(sharp.shape)
        clean = simulate_blur(sharp, np.asarray(summary["true_control_points"]), n_times=summary["render_n_times"])
        assert abs((blurred - clean).std() / summary["noise_sigma"] - 1) < 0.25, (blurred - clean).std()
        # the written deconvolved light field is the one whose PSNR the summary gives (10 log10(1 / MSE) over the
        # views without psnr_crop border pixels), and deconvolution with the known path beats the blurred input
        error = (read_lightfield(out / f"{name}_deconvolved.npz") - sharp.astype(np.float64))[:, :, c:-c, c:-c]
        assert abs(10 * np.log10(1 / np.mean(error ** 2)) - rec["psnr_db"]["deconvolved (path known)"]) < 0.01
        assert rec["psnr_db"]["deconvolved (path known)"] > rec["psnr_db"]["blurred"] + 1.0
    np.testing.assert_allclose(load_path_json(out / "synthetic_blurred.path.json"), summary["true_control_points"])
    # every light field it writes has the path beside it, and the summary lists exactly what is there
    np.testing.assert_allclose(load_path_json(out / "lytro_deconvolved.path.json"), summary["true_control_points"])
    # and states the instants it was blurred with (64: `lfdeblur deconvolve` of it used 32) and restored with
    from napari_lfdeblur import read_path_json

    for kind, n_times in (("blurred", summary["render_n_times"]), ("deconvolved", 32)):
        stated = read_path_json(out / f"synthetic_{kind}.path.json")[1]
        assert (stated["n_times"], stated["infinity_disparity"]) == (n_times, 0.0)
    assert sorted(summary["files"]) == sorted(p.name for p in out.iterdir())


def test_demo_is_reproducible(tmp_path):
    from napari_lfdeblur.demo import run_demo

    # the demo's noise is seeded: two runs write the same blurred light fields and report the same PSNRs
    first = run_demo(tmp_path / "a", device="cpu", quick=True, blind=False)
    second = run_demo(tmp_path / "b", device="cpu", quick=True, blind=False)
    for name in ("synthetic", "lytro"):
        a, b = (read_lightfield(tmp_path / run / f"{name}_blurred.npz") for run in ("a", "b"))
        np.testing.assert_array_equal(a, b)
        assert first["samples"][name]["psnr_db"] == second["samples"][name]["psnr_db"]


def test_demo_quick_blind_says_what_it_found(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--quick", "--device", "cpu"]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    for name, rec in summary["samples"].items():
        assert f"  blind: {rec['blind_message']}" in printed
        assert rec["blind_blur_found"] == rec["blind_message"].startswith("blur found")
        blurred, restored = (read_lightfield(out / f"{name}_{kind}.npz") for kind in ("blurred", "blind"))
        if rec["blind_blur_found"]:
            assert "blind_rejected_path" not in rec and not np.array_equal(restored, blurred)
            assert rec["blind_restoration"] == "full"
        elif rec["blind_restoration"] == "light":  # restored with the rejected path scaled, which the summary keeps
            assert not np.array_equal(restored, blurred)
            np.testing.assert_allclose(rec["blind_control_points"], 0.5 * np.asarray(rec["blind_rejected_path"]),
                                       atol=1e-12)
        else:  # the input comes back unchanged, and the summary keeps the path that was rejected
            assert rec["blind_restoration"] == "none"
            np.testing.assert_array_equal(restored, blurred)
            assert np.asarray(rec["blind_rejected_path"]).shape[1] == 3 and not np.any(rec["blind_control_points"])


def test_transposed_views_are_named_and_swapped_on_request(tmp_path, capsys):
    from _reference import moving_texture

    lf = moving_texture(n_views=5, d=1.0, size=32)
    np.save(tmp_path / "upright.npy", lf)
    np.save(tmp_path / "transposed.npy", lf.swapaxes(0, 1))

    assert main(["info", str(tmp_path / "transposed.npy")]) == 0
    out, err = capsys.readouterr()
    assert "look transposed" in err and "--swap-views" in err and "Traceback" not in err
    assert "view_shifts: [[0.0, 1.0], [1.0, 0.0]]" in out.replace("-0.0", "0.0")

    assert main(["info", "--swap-views", str(tmp_path / "transposed.npy")]) == 0
    out, err = capsys.readouterr()
    assert err == "" and "view_shifts: [[1.0, 0.0], [0.0, 1.0]]" in out.replace("-0.0", "0.0")

    assert main(["info", "--swap-views", str(tmp_path / "upright.npy")]) == 0
    assert "did not look transposed" in capsys.readouterr().err

    # --swap-views reads the light field the other way round: the blur is that of the upright one
    out = tmp_path / "blurred.npz"
    assert main(["simulate", "--swap-views", str(tmp_path / "transposed.npy"), str(out),
                 "--path", "linear:2", "--n-times", "8"]) == 0
    np.testing.assert_allclose(read_lightfield(out), simulate_blur(lf, linear_path(2.0), n_times=8), atol=1e-6)


def test_deblur_says_once_that_the_views_look_transposed(tmp_path, capsys, monkeypatch):
    from _reference import moving_texture

    from napari_lfdeblur import blind
    from napari_lfdeblur.progress import Progress

    np.save(tmp_path / "transposed.npy", moving_texture(n_views=5, d=1.0, size=32).swapaxes(0, 1))
    seen = []

    def fake_iter_blind_deblur(lf, **kwargs):
        seen.append(kwargs["check_view_order"])
        yield Progress("path", 1, 1, loss=1.0)
        return blind.BlindResult(lf, np.zeros((3, 3)), params=kwargs["params"])

    monkeypatch.setattr(blind, "iter_blind_deblur", fake_iter_blind_deblur)
    for extra in ([], ["--swap-views"]):
        out = tmp_path / f"o{len(extra)}.npz"
        assert main(["deblur", str(tmp_path / "transposed.npy"), str(out), "--device", "cpu", *extra]) == 0
        assert capsys.readouterr().err.count("look transposed") == (0 if extra else 1)  # the reader's, with its fix
    assert seen == [False, False]  # the solver does not check what the reader checked


@pytest.mark.parametrize("value", ["nan", "inf", "100"])
def test_deblur_refuses_a_bad_infinity_disparity_in_one_line(lf_file, tmp_path, capsys, value):
    _, src = lf_file
    out = tmp_path / "o.npz"
    assert main(["deblur", str(src), str(out), "--infinity-disparity", value, "--device", "cpu"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "infinity_disparity" in err and not out.exists()


def test_deblur_help_says_where_infinity_disparity_comes_from(capsys):
    with pytest.raises(SystemExit):
        main(["deblur", "--help"])
    assert "farthest" in " ".join(capsys.readouterr().out.split())


def test_simulate_states_t_and_infinity_disparity_and_deblur_uses_it(lf_file, tmp_path, capsys):
    from napari_lfdeblur.io import read_lightfield_with_metadata

    _, src = lf_file
    out = tmp_path / "b.npz"
    assert main(["simulate", str(src), str(out), "--path", "linear:1", "--n-times", "8",
                 "--infinity-disparity", "0.5"]) == 0
    _, meta = read_lightfield_with_metadata(out)
    assert meta["infinity_disparity"] == 0.5 and meta["n_times"] == 8
    doc = json.loads((tmp_path / "b.path.json").read_text())
    assert doc["infinity_disparity"] == 0.5 and doc["n_times"] == 8
    # a file that states an impossible d_inf: deblur takes it from the file, and refuses it in one line
    lf = np.random.default_rng(1).random((5, 5, 12, 12)).astype(np.float32)
    write_lightfield(tmp_path / "far.npz", lf, metadata={"infinity_disparity": 100.0})
    capsys.readouterr()
    assert main(["deblur", str(tmp_path / "far.npz"), str(tmp_path / "o.npz"), "--device", "cpu"]) == 2
    err = capsys.readouterr().err
    assert "as " in err and "states" in err and "infinity_disparity" in err.splitlines()[-1]
    assert not (tmp_path / "o.npz").exists()


@pytest.mark.filterwarnings("ignore:.*the views look transposed")  # random views, blurred
def test_simulate_takes_t_and_infinity_disparity_from_the_path_file(lf_file, tmp_path, capsys):
    lf, src = lf_file
    cp = np.array([[0.3, -0.2, 0.1], [-0.5, 0.4, -0.2], [0.8, 0.1, 0.0]])
    save_path_json(tmp_path / "p.json", cp, n_times=6, infinity_disparity=-0.5)
    capsys.readouterr()
    assert main(["simulate", str(src), str(tmp_path / "a.npz"), "--path", str(tmp_path / "p.json")]) == 0
    assert f"using infinity_disparity = -0.5, as {tmp_path / 'p.json'} states" in capsys.readouterr().err
    np.testing.assert_allclose(read_lightfield(tmp_path / "a.npz"),
                               simulate_blur(lf, cp, n_times=6, infinity_disparity=-0.5), atol=1e-6)
    doc = json.loads((tmp_path / "a.path.json").read_text())
    assert (doc["n_times"], doc["infinity_disparity"]) == (6, -0.5)
    # the flags win over the file
    assert main(["simulate", str(src), str(tmp_path / "b.npz"), "--path", str(tmp_path / "p.json"),
                 "--n-times", "4", "--infinity-disparity", "0"]) == 0
    np.testing.assert_allclose(read_lightfield(tmp_path / "b.npz"), simulate_blur(lf, cp, n_times=4), atol=1e-6)
    # a file stating an unusable T: one line, nothing written
    (tmp_path / "bad.json").write_text(json.dumps({"control_points": cp.tolist(), "n_times": "many"}))
    capsys.readouterr()
    assert main(["simulate", str(src), str(tmp_path / "c.npz"), "--path", str(tmp_path / "bad.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "n_times" in err and not (tmp_path / "c.npz").exists()


def test_simulate_shake6_writes_a_6_column_path(lf_file, tmp_path, capsys):
    lf, src = lf_file
    out = tmp_path / "b.npz"
    assert main(["simulate", str(src), str(out), "--path", "shake6:1.5:3:0.02", "--n-times", "8"]) == 0
    assert f"T and d_inf: {tmp_path / 'b.path.json'} (6-DOF, rotation up to 20.00 mrad)" in capsys.readouterr().out
    cp = load_path_json(tmp_path / "b.path.json")
    assert cp.shape == (5, 6) and "radians" in (tmp_path / "b.path.json").read_text()
    np.testing.assert_allclose(cp, preset_path("shake6", 1.5, 3, rotation=0.02))
    np.testing.assert_allclose(read_lightfield(out), simulate_blur(lf, cp, n_times=8), atol=1e-6)
    # without ROTATION: the default rotation, still 6 columns
    assert main(["simulate", str(src), str(tmp_path / "c.npz"), "--path", "shake6:1:3", "--n-times", "4"]) == 0
    np.testing.assert_allclose(load_path_json(tmp_path / "c.path.json"), preset_path("shake6", 1.0, 3))


def test_info_describes_a_camera_path_file(tmp_path, capsys):
    # a straight motion of 2 views at 30 degrees, sampled at its two ends: 2 views across and travelled
    save_path_json(tmp_path / "line.json", linear_path(length=2.0, angle_deg=30.0), n_times=5, note="mine")
    assert main(["info", str(tmp_path / "line.json")]) == 0
    out = capsys.readouterr().out
    assert "3-DOF, 2 control points" in out and "extent:      2 views in (p_x, p_y) over the exposure (5 instants); " \
        "2 views travelled" in out
    assert "p_z:         0 (in-plane motion)" in out and 'note: "mine"' in out and "rotation" not in out
    # out of plane: p_z from -0.4 to 0.4 (its control points, a straight Bezier reaches both); a rotation
    cp = np.array([[0.0, 0.0, -0.4, 0.0, 0.0, 0.0], [0.0, 0.0, 0.4, 0.003, -0.02, 0.001]])
    save_path_json(tmp_path / "z.json", cp)
    assert main(["info", str(tmp_path / "z.json")]) == 0
    out = capsys.readouterr().out
    assert "6-DOF, 2 control points" in out and "p_z:         -0.4 to 0.4" in out
    assert "rotation:    up to 20.00 mrad (1.15 deg; pitch r_x 3.00, yaw r_y 20.00, roll r_z 1.00" in out
    assert "extent:      0 views" in out and "does not blur" not in out  # it zooms
    save_path_json(tmp_path / "still.json", np.zeros((3, 3)))
    assert main(["info", str(tmp_path / "still.json")]) == 0
    assert "this path does not blur" in capsys.readouterr().out
    # a light field that holds its path: described with it
    write_lightfield(tmp_path / "b.npz", np.zeros((3, 3, 4, 4), np.float32), metadata={"n_times": 5},
                     control_points=linear_path(length=2.0, angle_deg=30.0))
    assert main(["info", str(tmp_path / "b.npz")]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"file:        {tmp_path / 'b.npz'}\n") and "camera path:\n  motion:      3-DOF, 2 control points" in out and "  extent:      2 views" in out
    # not a path: one line, no traceback
    (tmp_path / "bad.json").write_text('{"control_points": [[1, 2]]}')
    assert main(["info", str(tmp_path / "bad.json")]) == 2
    err = capsys.readouterr().err
    assert "bad.json" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_an_output_that_cannot_be_written_is_refused_before_any_solve(lf_file, tmp_path, monkeypatch, capsys):
    from napari_lfdeblur import blind, deconvolution

    _, src = lf_file

    def never(*args, **kwargs):
        raise AssertionError("the solve ran")

    monkeypatch.setattr(blind, "iter_blind_deblur", never)
    monkeypatch.setattr(deconvolution, "iter_deconvolve", never)
    save_path_json(tmp_path / "p.json", linear_path(1.0))
    for args in (["deblur", str(src), str(tmp_path / "o.png")],
                 ["deconvolve", str(src), str(tmp_path / "p.json"), str(tmp_path / "o.jpg")]):
        assert main(args) == 2
        assert "cannot tell the format from the suffix" in capsys.readouterr().err
    # nor into a folder that does not exist
    for args in (["deblur", str(src), str(tmp_path / "no" / "o.npz")],
                 ["deconvolve", str(src), str(tmp_path / "p.json"), str(tmp_path / "no" / "o.npz")]):
        assert main(args) == 2
        assert "the folder" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lf.npy", "p.json"]


def test_info_describes_a_batch_output_folder(tmp_path, capsys):
    # the last record of each output counts (a.npz failed, then was redone)
    def rec(output, status, **extra):
        return json.dumps({"kind": "deblur", "version": "9.9", "output": output, "status": status,
                           "error": None if status == "ok" else "OSError: disk full", **extra})

    lines = [rec("a.npz", "failed"), rec("a.npz", "ok", blur_found=True, restoration="full"),
             rec("b.npz", "ok", blur_found=False, restoration="light"),
             rec("c.npz", "ok", blur_found=False, restoration="none"), rec("d.npz", "failed"), '{"truncated']
    (tmp_path / "manifest.jsonl").write_text("\n".join(lines) + "\n")
    assert main(["info", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "(lfdeblur batch deblur; napari-lfdeblur 9.9)" in out and "4 in the manifest: 3 done, 1 failed" in out
    assert "failed:      d.npz: OSError: disk full" in out and "a.npz" not in out
    assert "blur found:  in 1 of 3; 1 with little blur found, returned unchanged" in out and "restored lightly" in out
    assert "redoes the failed items" in out
    (tmp_path / "manifest.jsonl").write_text("")  # a batch that has not finished an item yet
    assert main(["info", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "none in the manifest yet" in out and "?" not in out


@pytest.mark.parametrize("motion", [None, "3dof", "6dof"])
def test_deblur_motion_reaches_the_params_and_a_6_column_path_is_saved(lf_file, tmp_path, monkeypatch, motion):
    from napari_lfdeblur import blind
    from napari_lfdeblur.progress import Progress

    _, src = lf_file
    seen = {}

    def fake_iter_blind_deblur(lf, *, infinity_disparity, params, device, seed, max_memory=None, windows=None,
                               check_view_order=True):
        seen["params"] = params
        yield Progress("path", 1, 1, loss=1.0)
        cp = preset_path("shake6", 1.0, 0)
        return blind.BlindResult(lf, cp if params.motion == "6dof" else cp[:, :3], params=params)

    monkeypatch.setattr(blind, "iter_blind_deblur", fake_iter_blind_deblur)
    params_file = tmp_path / "p.json"
    params_file.write_text(json.dumps({"n_control_points": 5, "n_times": 8, "path": {"n_outer": 1}}))
    args = ["deblur", str(src), str(tmp_path / "o.npz"), "--params", str(params_file), "--device", "cpu"]
    assert main(args + (["--motion", motion] if motion else [])) == 0
    params = seen["params"]
    assert params.motion == (motion or "3dof") and params.n_control_points == 5 and params.path.n_outer == 1
    # the path goes where reading the result back finds it; the file states the parameters and the version
    result, meta = read_lightfield_with_metadata(tmp_path / "o.npz")
    cp = load_path_json(tmp_path / "o.path.json")
    assert cp.shape == ((5, 6) if motion == "6dof" else (5, 3))
    np.testing.assert_array_equal(meta["control_points"], cp)
    saved = meta["saved_metadata"]
    assert saved["motion"] == (motion or "3dof") and saved["napari_lfdeblur_version"] == napari_lfdeblur.__version__
    assert BlindParams.from_dict(saved["parameters"]) == params and saved["preset"] is None  # --params, no preset
    assert BlindParams.from_metadata(meta) == BlindParams.from_metadata(saved) == params  # the file's stamp
    # the instants it was restored with (final_n_times, not the path stage's 8), and the seed
    assert saved["n_times"] == json.loads((tmp_path / "o.path.json").read_text())["n_times"] == params.final_n_times
    assert saved["seed"] == 0


def test_deblur_keeps_a_rejected_path_and_prints_the_command_that_restores_with_it(lf_file, tmp_path, monkeypatch,
                                                                                  capsys):
    import shlex

    from napari_lfdeblur import blind, deconvolve
    from napari_lfdeblur.progress import Progress

    lf, src = lf_file
    rejected = linear_path(1.5, 30.0)

    # the evidence test says no
    def fake_iter_blind_deblur(lf, *, infinity_disparity, params, device, seed, max_memory=None, windows=None,
                               check_view_order=True):
        yield Progress("path", 1, 1, loss=1.0)
        return blind.BlindResult(lf, np.zeros((3, 3)), params=params,
                                 info={"blur_found": False, "message": "little blur found", "rejected_path": rejected})

    monkeypatch.setattr(blind, "iter_blind_deblur", fake_iter_blind_deblur)
    args = ["deblur", str(src), str(tmp_path / "o.npz"), "--device", "cpu", "--infinity-disparity", "0.5",
            "--value-range", "0,2"]
    assert main(args) == 0
    printed = capsys.readouterr().out.splitlines()
    np.testing.assert_allclose(load_path_json(tmp_path / "o.path_rejected.json"), rejected)
    command = shlex.split(printed[printed.index("little blur found") + 1].split("again: ")[1])
    assert command[:2] == ["lfdeblur", "deconvolve"] and "OUTPUT" in command
    # the printed command restores with the rejected path, at the d_inf the file records, from the data read
    # as deblur read them (the value range too)
    command = [str(tmp_path / "r.npz") if word == "OUTPUT" else word for word in command]
    assert main([*command[1:], "--device", "cpu", "--iterations", "5"]) == 0
    expected = deconvolve(lf / 2, rejected, infinity_disparity=0.5, n_iter=5, device="cpu")
    np.testing.assert_allclose(read_lightfield(tmp_path / "r.npz"), expected, atol=1e-5)
    # a second run would replace the rejected path's file: refused without --overwrite
    (tmp_path / "o.npz").unlink()
    (tmp_path / "o.path.json").unlink()
    assert main(args) == 2
    assert "o.path_rejected.json exists" in capsys.readouterr().err and not (tmp_path / "o.npz").exists()
    # with --path-out, a copy of the path there and the rejected one beside it
    assert main(args + ["--overwrite", "--path-out", str(tmp_path / "p.json")]) == 0
    np.testing.assert_array_equal(load_path_json(tmp_path / "p.json"), load_path_json(tmp_path / "o.path.json"))
    np.testing.assert_allclose(load_path_json(tmp_path / "p_rejected.json"), rejected)
    # every path file states the views it belongs to
    for name in ("p.json", "p_rejected.json", "o.path.json"):
        assert json.loads((tmp_path / name).read_text())["view_shape"] == list(lf.shape[2:4])
    # a run that rejects nothing removes an earlier run's rejected path (it would pass for this run's)
    def finds_blur(lf, **kwargs):
        yield Progress("path", 1, 1, loss=1.0)
        return blind.BlindResult(lf, rejected, params=kwargs["params"], info={"blur_found": True})

    monkeypatch.setattr(blind, "iter_blind_deblur", finds_blur)
    assert main(args + ["--overwrite"]) == 0 and not (tmp_path / "o.path_rejected.json").exists()
    # --path-out may not name the output (the light field became a path file) nor the input
    before = (tmp_path / "o.npz").stat().st_mtime_ns
    assert main(args + ["--overwrite", "--path-out", str(tmp_path / "o.npz")]) == 2
    assert "named for two of this command's outputs" in capsys.readouterr().err
    assert main(args + ["--overwrite", "--path-out", str(src)]) == 2
    assert "is the input" in capsys.readouterr().err
    assert (tmp_path / "o.npz").stat().st_mtime_ns == before and read_lightfield(src).shape == lf.shape
    # a --path-out into a missing folder: refused before the solve, the output left as it was
    before = (tmp_path / "o.npz").stat().st_mtime_ns
    assert main(args + ["--overwrite", "--path-out", str(tmp_path / "no" / "p.json")]) == 2
    assert "does not exist" in capsys.readouterr().err and (tmp_path / "o.npz").stat().st_mtime_ns == before


def test_deblur_progress_on_a_terminal_and_in_a_log(lf_file, tmp_path, monkeypatch, capsys):
    import sys

    from napari_lfdeblur import blind
    from napari_lfdeblur.progress import Progress

    _, src = lf_file

    def fake_iter_blind_deblur(lf, *, infinity_disparity, params, device, seed, max_memory=None, windows=None,
                               check_view_order=True):
        yield Progress("path", 1, 4, loss=0.125)
        for _ in range(500):  # a solver reports hundreds of times a second
            yield Progress("path", 2, 4)  # inside a path-fit step: NaN loss
        yield Progress("path", 3, 4)
        yield Progress("final", 1, 200, loss=7.0, stage_index=1, n_stages=2, info={"relative_decrease": 0.01})
        return blind.BlindResult(lf, np.zeros((3, 3)), params=params)

    monkeypatch.setattr(blind, "iter_blind_deblur", fake_iter_blind_deblur)
    args = ["deblur", str(src), str(tmp_path / "o.npz"), "--device", "cpu", "--overwrite"]
    # in a log (stderr not a terminal): one line per stage, no bar
    assert main(args) == 0
    lines = capsys.readouterr().err.splitlines()
    assert "\r" not in "".join(lines)
    assert [line.split(" (")[0] for line in lines] == ["lfdeblur deblur: path", "lfdeblur deblur: final"]
    # on a terminal: a bar, redrawn when the stage changes and a few times a second, not at every record
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "loss 0.125" in err and "nan" not in err
    assert err.count("\r") < 50
    # the path stage's bar gives the time left; the final TV solve's, which stops when it settles, does not
    shown = [line for line in err.split("\r") if "loss" in line]
    assert all("<" in line for line in shown if line.startswith("path"))
    assert any(line.startswith("final") for line in shown)
    assert not any("<" in line for line in shown if line.startswith("final"))


def test_deblur_help_describes_motion(capsys):
    with pytest.raises(SystemExit):
        main(["deblur", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--motion {3dof,6dof}" in text and "slower" in text and "rotation" in text


@pytest.mark.parametrize("option, values, received, bad, message", [
    # the help: a FRACTION in [0, 1], both ends taken (the preset 'default' has 0.5)
    pytest.param("--light-restoration", ["0.25", "0", "1"], [0.5, 0.25, 0.0, 1.0], ("1.5", "-0.1", "half"),
                 "expected a number in [0, 1]", id="light-restoration"),
    pytest.param("--max-memory", ["1.5"], [None, 3 * 2**29], ("0", "-2", "lots", "inf"),
                 "expected a positive number of GiB", id="max-memory"),
    pytest.param("--seed", ["5"], [0, 5], ("-1", "x"), "expected a whole number from 0 to 2**63 - 1", id="seed"),
    # a flag: BlindParams.require_evidence=False, as its help says (the presets require evidence)
    pytest.param("--restore-anyway", [None], [True, False], (), None, id="restore-anyway"),
])
def test_deblur_options_reach_the_solver_and_are_checked(option, values, received, bad, message, lf_file, tmp_path,
                                                         monkeypatch, capsys):
    from napari_lfdeblur import blind
    from napari_lfdeblur.progress import Progress

    _, src = lf_file
    seen = []

    def fake_iter_blind_deblur(lf, *, infinity_disparity, params, device, seed, max_memory=None, windows=None,
                               check_view_order=True):
        seen.append({"--light-restoration": params.light_restoration, "--max-memory": max_memory, "--seed": seed,
                     "--restore-anyway": params.require_evidence}[option])
        yield Progress("path", 1, 1, loss=1.0)
        return blind.BlindResult(lf, np.zeros((3, 3)), params=params)

    monkeypatch.setattr(blind, "iter_blind_deblur", fake_iter_blind_deblur)
    assert main(["deblur", str(src), str(tmp_path / "o.npz"), "--device", "cpu"]) == 0
    for value in values:
        given = [option] if value is None else [option, value]
        assert main(["deblur", str(src), str(tmp_path / "o.npz"), "--device", "cpu", "--overwrite", *given]) == 0
    assert seen == received
    capsys.readouterr()
    for text in bad:
        with pytest.raises(SystemExit):
            main(["deblur", str(src), str(tmp_path / "x.npz"), option, text])
        assert message in capsys.readouterr().err
    assert len(seen) == 1 + len(values) and not (tmp_path / "x.npz").exists()


def _spy_on_deconvolve(monkeypatch) -> list:
    """The keyword arguments of each call of the solver the command runs (the real one, which still runs), and
    its control points as ``'control_points'``."""
    from napari_lfdeblur import deconvolution

    real, seen = deconvolution.iter_deconvolve, []

    def spy(*args, **kwargs):
        seen.append({**kwargs, "control_points": np.asarray(args[1] if len(args) > 1 else kwargs["control_points"])})
        return (yield from real(*args, **kwargs))

    monkeypatch.setattr(deconvolution, "iter_deconvolve", spy)
    return seen


def test_deconvolve_tol_reaches_the_solver(lf_file, tmp_path, monkeypatch, capsys):
    _, src = lf_file
    save_path_json(tmp_path / "p.json", linear_path(1.0))
    seen = _spy_on_deconvolve(monkeypatch)
    assert main(["deconvolve", str(src), str(tmp_path / "p.json"), str(tmp_path / "d.npz"), "--tol", "0",
                 "--iterations", "3", "--device", "cpu"]) == 0
    assert (seen[0]["tol"], seen[0]["n_iter"]) == (0.0, 3)
    assert "3 iteration(s)" in capsys.readouterr().out  # tol 0: no early stop
    saved = read_lightfield_with_metadata(tmp_path / "d.npz")[1]["saved_metadata"]["parameters"]
    assert saved["tol"] == 0.0  # the file states the tolerance it was restored with


def test_deconvolve_inplane_refuses_the_tv_options_it_would_not_use(lf_file, tmp_path, monkeypatch, capsys):
    _, src = lf_file
    save_path_json(tmp_path / "p.json", linear_path(1.0))
    seen = _spy_on_deconvolve(monkeypatch)
    for flags in (["--along-views"], ["--iterations", "5", "--tol", "0"]):
        assert main(["deconvolve", str(src), str(tmp_path / "p.json"), str(tmp_path / "d.npz"),
                     "--method", "inplane", *flags]) != 0
        assert f"{flags[0]}" in capsys.readouterr().err
    assert seen == [] and not (tmp_path / "d.npz").exists()  # refused before any work
    assert main(["deconvolve", str(src), str(tmp_path / "p.json"), str(tmp_path / "d.npz"),
                 "--method", "inplane", "--weight", "0.01", "--device", "cpu"]) == 0
    assert seen[0]["method"] == "inplane" and seen[0]["weight"] == 0.01
    # the command's tv defaults (kept apart so that --help needs no torch) are the solver's own
    from napari_lfdeblur._cli_info import TV_ITERATIONS, TV_TOL
    from napari_lfdeblur.deconvolution import DeconvolutionParams

    assert (TV_ITERATIONS, TV_TOL) == (DeconvolutionParams().n_iter, DeconvolutionParams().tol)


def test_deconvolve_takes_t_from_the_path_file_else_32(lf_file, tmp_path, monkeypatch):
    lf, _ = lf_file
    write_lightfield(tmp_path / "b.npz", lf, metadata={"n_times": 8})  # the input states a T, its path file none
    save_path_json(tmp_path / "p.json", linear_path(1.0))
    save_path_json(tmp_path / "q.json", linear_path(1.0), n_times=6)
    seen = _spy_on_deconvolve(monkeypatch)
    for path_file, out in (("p.json", "d.npz"), ("q.json", "e.npz")):
        assert main(["deconvolve", str(tmp_path / "b.npz"), str(tmp_path / path_file), str(tmp_path / out),
                     "--iterations", "2", "--device", "cpu"]) == 0
    # --n-times' help: "default: those stated with the path, else 32" (not the input's)
    assert [kwargs["n_times"] for kwargs in seen] == [32, 6]


def test_deconvolve_takes_the_path_as_simulate_does(lf_file, tmp_path, monkeypatch, capsys):
    # --path: a preset (or a file), as `lfdeblur simulate --path` takes it; the preset's control points reach
    # the solver exactly, as its own file would bring them
    _, src = lf_file
    save_path_json(tmp_path / "p.json", preset_path("random", extent=1.0, seed=3))
    seen = _spy_on_deconvolve(monkeypatch)
    flags = ["--iterations", "2", "--device", "cpu"]
    assert main(["deconvolve", str(src), str(tmp_path / "p.json"), str(tmp_path / "a.npz"), *flags]) == 0
    assert main(["deconvolve", str(src), str(tmp_path / "b.npz"), "--path", "random:1:3", *flags]) == 0
    assert main(["deconvolve", str(src), str(tmp_path / "c.npz"), "--path", str(tmp_path / "p.json"), *flags]) == 0
    np.testing.assert_array_equal(seen[1]["control_points"], seen[0]["control_points"])
    np.testing.assert_array_equal(seen[2]["control_points"], seen[0]["control_points"])
    capsys.readouterr()
    # two paths, or a preset that is none: refused before any work, nothing written
    assert main(["deconvolve", str(src), str(tmp_path / "p.json"), str(tmp_path / "d.npz"), "--path",
                 "linear:1"]) == 2
    assert "two paths given" in capsys.readouterr().err
    assert main(["deconvolve", str(src), str(tmp_path / "e.npz"), "--path", "wobble:1"]) == 2
    assert "neither a JSON file nor a preset" in capsys.readouterr().err
    assert len(seen) == 3 and not (tmp_path / "d.npz").exists() and not (tmp_path / "e.npz").exists()


def test_a_closed_stdout_ends_the_command_quietly(lf_file):
    # `lfdeblur info X | head -1`: the reader goes away; no error message, the status of a broken pipe
    import subprocess
    import sys

    _, src = lf_file
    proc = subprocess.Popen([sys.executable, "-m", "napari_lfdeblur.cli", "info", str(src)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # before the command writes anything
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert err == ""


def test_no_command_prints_the_commands(capsys):
    assert main([]) == 2
    out = capsys.readouterr().out
    assert out.startswith("usage: lfdeblur") and all(c in out for c in ("info", "simulate", "deconvolve", "deblur"))


def test_python_dash_m_runs_the_command(tmp_path):
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-m", "napari_lfdeblur", "--version"], capture_output=True, text=True,
                         cwd=tmp_path, check=True)
    assert run.stdout.strip() == f"lfdeblur {napari_lfdeblur.__version__}"


def test_a_reader_warning_is_one_line(lf_file, tmp_path, capsys):
    _, src = lf_file
    (tmp_path / "lf.path.json").write_text('{"control_points": [[1, 2]]}')  # beside lf.npy, not a path
    assert main(["info", str(src)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert [line for line in err if "path.json" in line] == [
        f"lfdeblur info: warning: {tmp_path / 'lf.path.json'} was not read as the light field's camera path: "
        "control points must be an (n, 3) array of (p_x, p_y, p_z) or an (n, 6) array of (p_x, p_y, p_z, r_x, "
        "r_y, r_z); got shape (1, 2)"]


def test_bad_seeds_paths_and_output_folders_get_one_line(lf_file, tmp_path, capsys):
    _, src = lf_file
    for bad in ("-1", "99999999999999999999", "x"):
        with pytest.raises(SystemExit) as stop:
            main(["deblur", str(src), str(tmp_path / "d.npz"), "--seed", bad])
        assert stop.value.code == 2
        assert f"argument --seed: '{bad}': expected a whole number from 0 to 2**63 - 1" in capsys.readouterr().err
    for path, said in (("random:2:-5", "the SEED must be a whole number"), (str(tmp_path), "is a folder")):
        assert main(["simulate", str(src), str(tmp_path / "b.npz"), "--path", path]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and said in err
    (tmp_path / "afile").write_text("mine")
    assert main(["demo", "--out", str(tmp_path / "afile"), "--quick", "--skip-blind"]) == 2
    assert "afile is a file" in capsys.readouterr().err and (tmp_path / "afile").read_text() == "mine"


def test_a_folder_that_takes_no_file_is_refused_before_the_work(lf_file, tmp_path, capsys, monkeypatch):
    """A read-only output folder (here: one whose files cannot be created) was found after the whole run, and
    --path-out's after the light field was written, which a rerun then refused to replace."""
    import pathlib

    _, src = lf_file
    locked = tmp_path / "locked"
    locked.mkdir()
    touch = pathlib.Path.touch

    def refuse_in_locked(self, *args, **kwargs):
        if self.parent == locked:
            raise PermissionError(13, "Permission denied", str(self))
        return touch(self, *args, **kwargs)

    def never(*args, **kwargs):
        raise AssertionError("the blind solver ran")

    monkeypatch.setattr(pathlib.Path, "touch", refuse_in_locked)
    monkeypatch.setattr(napari_lfdeblur.blind, "iter_blind_deblur", never)
    for extra in ([str(locked / "d.npz")], [str(tmp_path / "d.npz"), "--path-out", str(locked / "p.json")]):
        assert main(["deblur", str(src), *extra]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "the folder" in err and "takes no new file (Permission denied)" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lf.npy", "locked"]  # nothing written


def test_library_hints_are_given_as_options(lf_file, tmp_path, capsys):
    _, src = lf_file
    assert main(["info", str(src), "--angular-size", "4"]) == 2  # a reader option the layout does not take
    err = capsys.readouterr().err
    assert "error: --angular-size does not apply to layout 'npy' (its options: --grid, --value-range, " in err
    assert "angular_size" not in err and "max_bytes" not in err
    np.save(tmp_path / "thin.npy", np.random.default_rng(0).random((3, 3, 1, 8)).astype(np.float32))
    save_path_json(tmp_path / "p.json", linear_path(1.0))
    assert main(["deconvolve", str(tmp_path / "thin.npy"), str(tmp_path / "p.json"), str(tmp_path / "t.npz")]) == 2
    assert capsys.readouterr().err.rstrip().endswith("(2 x 2 at least): pass --weight W")


def test_a_file_whose_own_path_is_malformed_is_read_with_a_warning(tmp_path, capsys):
    lf = np.random.default_rng(0).random((3, 3, 8, 8)).astype(np.float32)
    np.savez(tmp_path / "badcp.npz", lf=lf, control_points=np.zeros((2, 2)))
    assert main(["info", str(tmp_path / "badcp.npz")]) == 0
    captured = capsys.readouterr()
    assert "badcp.npz: the camera path it holds was not read" in captured.err and "(3, 3, 8, 8)" in captured.out
    np.save(tmp_path / "zeros.npy", np.zeros((5, 5, 16, 16), np.float32))  # flat views: nothing to register
    assert main(["info", str(tmp_path / "zeros.npy")]) == 0
    assert "warning" not in capsys.readouterr().err


def test_running_out_of_memory_is_one_line(lf_file, tmp_path, capsys, monkeypatch):
    import napari_lfdeblur.cli as cli

    def simulate(args):
        raise MemoryError("Unable to allocate 119. GiB for an array with shape (9, 9, 376, 541, 3)")

    monkeypatch.setattr(cli, "_run_simulate", simulate)
    _, src = lf_file
    assert main(["simulate", str(src), str(tmp_path / "b.npz"), "--path", "linear:2"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error: out of memory (Unable to allocate 119. GiB" in err


def test_the_gpu_running_out_of_memory_is_one_line(lf_file, tmp_path, capsys, monkeypatch):
    import torch

    import napari_lfdeblur.cli as cli

    def simulate(args):  # torch's error is a RuntimeError, which the command did not catch
        raise torch.cuda.OutOfMemoryError("CUDA out of memory. Tried to allocate 20.00 GiB\nmore lines")

    monkeypatch.setattr(cli, "_run_simulate", simulate)
    _, src = lf_file
    assert main(["simulate", str(src), str(tmp_path / "d.npz"), "--path", "linear:2"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error: the GPU ran out of memory (CUDA out of memory. Tried" in err
    assert "--device cpu" in err

    def broken(args):  # any other RuntimeError is a bug: its traceback stays
        raise RuntimeError("something else")

    monkeypatch.setattr(cli, "_run_simulate", broken)
    with pytest.raises(RuntimeError, match="something else"):
        main(["simulate", str(src), str(tmp_path / "d.npz"), "--path", "linear:2"])


def test_a_params_file_that_is_a_folder_is_named_as_one(lf_file, tmp_path, capsys):
    _, src = lf_file
    assert main(["deblur", str(src), str(tmp_path / "o.npz"), "--params", str(tmp_path)]) == 2
    assert f"parameter file {tmp_path} is a folder" in capsys.readouterr().err
    assert main(["deblur", str(src), str(tmp_path / "o.npz"), "--params", str(tmp_path / "none.json")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_an_output_beside_the_input_may_not_replace_the_inputs_path_file(lf_file, tmp_path, capsys):
    """b.tif writes its path to b.path.json, which holds the path of the input b.npy: --overwrite took it."""
    lf, src = lf_file
    blurred = tmp_path / "b.npy"
    assert main(["simulate", str(src), str(blurred), "--path", "arc:2", "--n-times", "8",
                 "--infinity-disparity", "0.5"]) == 0
    path_file = tmp_path / "b.path.json"
    kept = path_file.read_bytes()
    for command in (["deconvolve", str(blurred), str(tmp_path / "b.tif"), "--iterations", "2", "--overwrite"],
                    ["deblur", str(blurred), str(tmp_path / "b.tif"), "--overwrite"],
                    ["simulate", str(blurred), str(tmp_path / "b.tif"), "--path", "linear:1", "--overwrite"]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert f"{path_file} holds the camera path of the input {blurred}" in err, err
        assert path_file.read_bytes() == kept and not (tmp_path / "b.tif").exists()
    # the input keeps its path: it deconvolves as before
    assert main(["deconvolve", str(blurred), str(tmp_path / "d.npz"), "--iterations", "2"]) == 0


def test_demo_replaces_only_its_own_files(tmp_path, capsys, monkeypatch):
    out = tmp_path / "project"
    out.mkdir()
    (out / "summary.json").write_text('{"my": "results"}')  # a file of the user's, of a name the demo writes
    (out / "notes.txt").write_text("mine")
    assert main(["demo", "--out", str(out), "--quick", "--skip-blind"]) == 2
    assert "summary.json exists and is not the demo's" in capsys.readouterr().err
    with monkeypatch.context() as m:  # --out "$UNSET": refused, not read as the current folder
        m.chdir(out)
        assert main(["demo", "--out", "", "--quick", "--skip-blind"]) == 2
    assert "empty name" in capsys.readouterr().err
    assert (out / "summary.json").read_text() == '{"my": "results"}' and sorted(p.name for p in out.iterdir()) == [
        "notes.txt", "summary.json"]
    # an earlier demo's files are its own: a rerun replaces them, and removes those it does not make
    demo = tmp_path / "demo"
    assert main(["demo", "--out", str(demo), "--quick", "--skip-blind"]) == 0
    (demo / "synthetic_blind.npz").write_bytes(b"stale")  # as a run with the blind solver left them
    summary = json.loads((demo / "summary.json").read_text())
    summary["files"].append("synthetic_blind.npz")
    (demo / "summary.json").write_text(json.dumps(summary))
    assert main(["demo", "--out", str(demo), "--quick", "--skip-blind"]) == 0
    assert not (demo / "synthetic_blind.npz").exists()
    assert sorted(json.loads((demo / "summary.json").read_text())["files"]) == sorted(p.name for p in demo.iterdir())


def test_errors_give_the_command_lines_options_not_python_keywords(lf_file, tmp_path, capsys):
    import torch

    lf, src = lf_file
    np.save(tmp_path / "stack.npy", lf[0])  # 3D: views without their grid
    assert main(["info", str(tmp_path / "stack.npy")]) == 2
    err = capsys.readouterr().err
    assert "pass --grid V,U" in err and "--layout eslf or --layout mosaic" in err and "grid=" not in err
    assert main(["simulate", str(src), str(tmp_path / "o.txt"), "--path", "linear:1"]) == 2
    err = capsys.readouterr().err  # no layout= to pass here: the suffix says the format
    assert "use .npz, .npy, .tif, .h5, a folder name without suffix" in err and "layout=" not in err
    if not torch.cuda.is_available():
        assert main(["demo", "--out", str(tmp_path / "d"), "--device", "cuda"]) == 2
        assert "use --device auto or cpu" in capsys.readouterr().err


def test_simulate_help_states_the_preset_defaults_it_uses(lf_file, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "EXTENT in views, default 2" in text and "SEED for shake, shake6 and random, default 0" in text
    _, src = lf_file
    for short, full in [("linear", "linear:2"), ("shake", "shake:2:0"), ("random", "random:2:0")]:
        assert main(["simulate", str(src), str(tmp_path / f"{short}.npz"), "--path", short, "--device", "cpu"]) == 0
        assert main(["simulate", str(src), str(tmp_path / f"{short}_full.npz"), "--path", full,
                     "--device", "cpu"]) == 0
        np.testing.assert_array_equal(load_path_json(tmp_path / f"{short}.path.json"),
                                      load_path_json(tmp_path / f"{short}_full.path.json"))
    np.testing.assert_allclose(np.ptp(load_path_json(tmp_path / "linear.path.json")[:, 0]), 2.0)  # 2 views long
