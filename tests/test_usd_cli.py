"""`zooctl bank export` end to end, and the exporters/importers as registered plugins."""

from __future__ import annotations

import numpy as np
from cli_helpers import run_inprocess, zooctl

from zooctl.io.gltf_import import load_gltf
from zooctl.io.rig_compare import posed_error_bound
from zooctl.io.usd_import import load_usd


def test_plugins_register_exporters_and_importers():
    from zooctl.plugins import get_registry

    reg = get_registry()
    assert reg.exporter_for("usdz").name == "usd" and reg.exporter_for("usda").name == "usd"
    assert reg.exporter_for("glb").name == "glb"
    for suffix in (".usd", ".usda", ".usdc", ".usdz"):
        assert reg.importer_for(suffix).name == "usd"
    for suffix in (".fbx", ".dae", ".bvh"):
        assert reg.importer_for(suffix).name == "assimp"


def test_export_formats_and_clips(store, tmp_path, capsys):
    assert run_inprocess(capsys, "bank", "seed", "--plan", "quadruped", "--no-variants").code == 0
    from zooctl.store.bank import Bank

    asset = Bank.open(store).get("quadruped")
    r = run_inprocess(
        capsys,
        "bank",
        "export",
        "quadruped",
        "--format",
        "usdz",
        "--clip",
        "trot",
        "-o",
        str(tmp_path / "q"),
        "--json",
    )
    assert r.code == 0, r.err
    info = r.json()
    assert info["path"].endswith("q.usdz") and info["clips"] == ["trot"]
    back = load_usd(tmp_path / "q.usdz", "back")
    assert list(back.clips) == ["trot"]
    assert posed_error_bound(asset, back, ["trot"]) <= 1e-4 * asset.size()
    r = run_inprocess(capsys, "bank", "export", "quadruped", "--all-clips", "-o", str(tmp_path / "q.glb"))
    assert r.code == 0, r.err
    assert list(load_gltf(tmp_path / "q.glb", "q").clips) == ["walk", "trot", "idle"]
    r = run_inprocess(
        capsys, "bank", "export", "quadruped", "-f", "usda", "--camera", "-o", str(tmp_path / "q.usda")
    )
    assert r.code == 0, r.err
    text = (tmp_path / "q.usda").read_text()
    assert text.startswith("#usda") and 'def Camera "Camera"' in text
    # What we export comes back in through `bank add` (the USD importer plugin).
    r = run_inprocess(capsys, "bank", "add", str(tmp_path / "q.usdz"), "--name", "again")
    assert r.code == 0, r.err
    np.testing.assert_allclose(
        Bank.open(store).get("again").pose("trot", 4), asset.pose("trot", 4), atol=1e-4 * asset.size()
    )


def test_export_usage_errors(store, tmp_path, capsys):
    assert run_inprocess(capsys, "bank", "seed", "--plan", "fish", "--no-variants").code == 0
    cases = [
        (("fish", "--format", "usdz", "-o", str(tmp_path / "x.glb")), "writes .usdz files"),
        (("fish", "-o", str(tmp_path / "x.obj")), "cannot tell an export format"),
        (("fish", "--format", "fbx"), "unknown export format 'fbx'"),
        (("fish", "--clip", "swim", "--all-clips", "-o", str(tmp_path / "x.glb")), "cannot be used together"),
        (("fish", "--clip", "fly", "-o", str(tmp_path / "x.glb")), "no clip 'fly'"),
        (("whale", "-o", str(tmp_path / "x.glb")), "no asset named 'whale'"),
        (("fish", "--camera", "-o", str(tmp_path / "x.glb")), "--camera is for USD exports"),
        (("fish", "-o", str(tmp_path / "missing" / "x.glb")), "does not exist"),
    ]
    for args, msg in cases:
        r = run_inprocess(capsys, "bank", "export", *args)
        assert r.code == 2 and msg in r.err and "Traceback" not in r.err, (args, r.err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["store"]  # nothing written


def test_export_through_the_console_script(store, tmp_path):
    assert zooctl("bank", "seed", "--plan", "snake", "--no-variants").code == 0
    r = zooctl("bank", "export", "snake", "-o", str(tmp_path / "snake.usd"))
    assert r.code == 0, r.err
    assert (tmp_path / "snake.usd").read_bytes()[:8] == b"PXR-USDC"


def test_export_into_a_folder_and_unwritable_places(store, tmp_path, capsys):
    """Issue 18 item 5: -o an existing folder writes NAME.suffix inside it; an unwritable -o is one
    clear error (not a FileNotFoundError on the temporary)."""
    import os
    import stat

    assert run_inprocess(capsys, "bank", "seed", "--plan", "fish", "--no-variants").code == 0
    folder = tmp_path / "out"
    folder.mkdir()
    r = run_inprocess(capsys, "bank", "export", "fish", "--format", "glb", "-o", str(folder), "--json")
    assert r.code == 0, r.err
    assert r.json()["path"] == str(folder / "fish.glb") and (folder / "fish.glb").is_file()
    assert not (tmp_path / "out.glb").exists()
    # a trailing slash names a folder even when it does not exist yet: made, not a file "new.glb"
    r = run_inprocess(capsys, "bank", "export", "fish", "--format", "glb", "-o", f"{tmp_path / 'new'}/")
    assert r.code == 0 and (tmp_path / "new" / "fish.glb").is_file(), r.err
    assert not (tmp_path / "new.glb").exists()
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        targets = [str(locked / "x.glb"), "/proc/zooctl-export-test.glb"]
        for target in targets:
            if target.startswith(str(locked)) and os.access(locked, os.W_OK):
                continue  # root writes anywhere: the /proc case still checks the error path
            r = run_inprocess(capsys, "bank", "export", "fish", "-o", target)
            assert r.code == 2 and "cannot write" in r.err and "Traceback" not in r.err, (target, r.err)
    finally:
        locked.chmod(stat.S_IRWXU)
    assert list(locked.iterdir()) == []
