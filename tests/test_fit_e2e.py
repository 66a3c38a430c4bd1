"""End to end: a procedural animal rendered by `bench make` code, fitted by the real `zooctl fit`.

Small on purpose (10 frames, 96 px, few iterations) so it runs in about a minute on a CPU; the
full-size runs are `bench/fit.py`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run_inprocess
from fit_helpers import small_quadruped_video

REPO = Path(__file__).resolve().parents[1]


def schema(name: str) -> dict:
    return json.loads((REPO / "schemas" / f"{name}.schema.json").read_text())


def validate_record(rec: dict) -> None:
    import jsonschema
    from referencing import Registry, Resource

    cfg = schema("fit_config")
    reg = Registry().with_resource("fit_config.schema.json", Resource.from_contents(cfg))
    reg = reg.with_resource(cfg["$id"], Resource.from_contents(cfg))
    jsonschema.Draft202012Validator(schema("fit_record"), registry=reg).validate(rec)


@pytest.fixture(scope="module")
def animal_video(tmp_path_factory):
    return small_quadruped_video(tmp_path_factory.mktemp("fit"))


@pytest.fixture(scope="module")
def fitted(animal_video, tmp_path_factory):
    """One real fit through the CLI (in-process), shared by the checks below."""
    store, folder, cfg = animal_video
    from cli_helpers import run_in_store

    code = run_in_store(
        store,
        "fit",
        str(folder),
        *("--template", "quadruped", "--config", str(cfg), "--name", "quad", "--json"),
        cwd=store.parent,  # outputs go to ./fits/NAME by default
    )
    assert code == 0
    rec = json.loads((store / "fits" / "quad" / "record.json").read_text())
    assert Path(rec["out"]) == (store.parent / "fits" / "quad").resolve()
    return store, rec


def test_fit_record_and_quality(fitted):
    store, rec = fitted
    validate_record(rec)
    assert rec["status"] == "done" and rec["template"] == "quadruped"
    m = rec["metrics"]
    # Same template as the animal: the silhouettes must match well even after a short fit.
    assert m["mask_iou"] > 0.75, m["mask_iou"]
    # The reported IoU is the exported mesh's at the input resolution; the fitted model's is beside it
    # (they differ only by the displacement LBS does not skin).
    assert "exported mesh" in m["mask_iou_measured"] and "given" in m["mask_iou_measured"]
    assert abs(m["mask_iou"] - m["mask_iou_model"]) < 0.05 and m["novel_view_iou"] is not None
    assert 0.0 <= m["surface_tear"] < 0.05  # the procedural template, fitted to its own video
    for k in ("miou", "mcham", "joint", "skinning", "reanimation"):
        assert m[k] is not None and np.isfinite(m[k]), k
    assert m["miou"] > 0.3 and m["joint"] < 0.2
    fit_json = json.loads(Path(rec["outputs"]["fit_json"]).read_text())
    validate_record(fit_json)
    import jsonschema

    jsonschema.validate(
        json.loads((store / "fits" / "quad" / "config.json").read_text()), schema("fit_config")
    )
    assert rec["losses"]["stage1"]["steps"] == 12 and rec["losses"]["stage2"]["steps"] == 16


def test_fit_outputs_usd_glb_video(fitted):
    from pxr import Usd, UsdGeom, UsdSkel, UsdValidation

    from zooctl.io.video import probe_codec

    store, rec = fitted
    out = rec["outputs"]
    stage = Usd.Stage.Open(out["usd"])
    reg = UsdValidation.ValidationRegistry()
    errors = UsdValidation.ValidationContext(reg.GetOrLoadAllValidators()).Validate(stage)
    assert not [e for e in errors if e.GetType() == UsdValidation.ValidationErrorType.Error]
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera"))
    assert cam and cam.GetFocalLengthAttr().Get() > 0
    anims = [p for p in stage.Traverse() if p.IsA(UsdSkel.Animation)]
    assert len(anims) == 1
    times = anims[0].GetAttribute("rotations").GetTimeSamples()
    assert len(times) == rec["frames"]
    assert Path(out["glb"]).stat().st_size > 1000
    assert probe_codec(out["overlay"]) == "h264"
    from PIL import Image

    assert Image.open(out["loss_png"]).size[0] > 100


def test_usd_camera_projects_onto_the_masks(fitted, animal_video):
    """The exported camera and animation reproduce the fit's overlay: IoU with the input masks."""
    import torch
    from pxr import Usd, UsdGeom

    from zooctl.render.camera import from_usd
    from zooctl.render.raster import rasterize
    from zooctl.store.fits import FitStore

    store, rec = fitted
    _, folder, _ = animal_video
    asset = FitStore(store).character("quad")
    stage = Usd.Stage.Open(rec["outputs"]["usd"])
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera"))
    c2w = np.array(UsdGeom.Xformable(cam).ComputeLocalToWorldTransform(0)).T
    H, W = rec["image_size"]
    camera = from_usd(
        cam.GetFocalLengthAttr().Get(),
        cam.GetHorizontalApertureAttr().Get(),
        cam.GetVerticalApertureAttr().Get(),
        c2w,
        H,
        W,
    )
    masks = np.load(folder / "video.npz")["masks"]
    t = 5
    v = torch.as_tensor(asset.pose("fit", t)[None], dtype=torch.float32)
    sil = rasterize(v, torch.as_tensor(asset.faces, dtype=torch.long), camera).mask[0].numpy()
    iou = (sil & masks[t]).sum() / (sil | masks[t]).sum()
    assert iou > 0.7, iou


def test_fits_cli_list_show_export_rm(fitted, capsys, tmp_path, monkeypatch):
    store, _ = fitted
    monkeypatch.setenv("ZOOCTL_STORE", str(store))
    r = run_inprocess(capsys, "fits", "list", "--json")
    assert r.code == 0 and [x["name"] for x in r.json()] == ["quad"]
    r = run_inprocess(capsys, "fits", "show", "quad")
    assert r.code == 0 and "quadruped" in r.out
    r = run_inprocess(capsys, "fits", "export", "quad", "--out", str(tmp_path / "q.usda"))
    assert r.code == 0 and "SkelAnimation" in (tmp_path / "q.usda").read_text()
    r = run_inprocess(capsys, "fits", "show", "nope")
    assert r.code == 2 and "error:" in r.err and "Traceback" not in r.err
