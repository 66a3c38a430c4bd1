"""USD import of damaged files (issue 18): one clear error line, and USD's C++ diagnostics silenced."""

from __future__ import annotations

import pytest
from gltf_builder import write_tiny_glb

from zooctl.errors import InputError
from zooctl.io.gltf_import import load_gltf
from zooctl.io.usd_import import load_usd

pytest.importorskip("pxr")

JOINTS = 'uniform token[] joints = ["root", "root/tip"]'


@pytest.fixture
def tiny_usda(tmp_path):
    from zooctl.io.usd_export import save_usd

    asset = load_gltf(write_tiny_glb(tmp_path / "tiny.glb"), "tiny")
    save_usd(asset, tmp_path / "tiny.usda")
    text = (tmp_path / "tiny.usda").read_text()
    assert JOINTS in text
    return tmp_path / "tiny.usda", text


@pytest.mark.parametrize(
    "joints,match",
    [
        ('["root", "root"]', "lists joint 'root' twice"),
        ('["root/tip", "root"]', "lists joint 'root/tip' before its parent 'root'"),
    ],
)
def test_bad_joint_lists_are_clear_errors(tiny_usda, capfd, joints, match):
    path, text = tiny_usda
    path.write_text(text.replace(JOINTS, f"uniform token[] joints = {joints}"))
    with pytest.raises(InputError, match=match):
        load_usd(path, "bad")
    assert capfd.readouterr().err == ""  # USD's "invalid topology" warning is trapped


def test_cyclic_and_missing_sublayers_are_one_line_without_usd_noise(tiny_usda, capfd):
    path, _ = tiny_usda
    a, b = path.parent / "a.usda", path.parent / "b.usda"
    a.write_text("#usda 1.0\n(\n    subLayers = [@b.usda@, @tiny.usda@]\n)\n")
    b.write_text("#usda 1.0\n(\n    subLayers = [@a.usda@]\n)\n")
    with pytest.raises(InputError, match="layers do not compose: Sublayer hierarchy .* has cycles") as err:
        load_usd(a, "cyc")
    assert "\n" not in err.value.message
    c = path.parent / "c.usda"  # a new name: USD keeps layers it opened in this process
    c.write_text("#usda 1.0\n(\n    subLayers = [@tiny.usda@, @missing.usda@]\n)\n")
    with pytest.raises(InputError, match="its sublayer 'missing.usda' is missing"):
        load_usd(c, "missing")
    assert capfd.readouterr().err == ""
    # the same through the CLI: the error and its hint, nothing else
    from cli_helpers import zooctl

    r = zooctl("bank", "add", str(a), store=path.parent / "store")
    assert r.code == 2 and len(r.err.strip().splitlines()) == 2 and "Warning" not in r.err, r.err


def test_unreadable_usd_and_long_animation(tiny_usda, capfd):
    path, text = tiny_usda
    bad = path.parent / "garbage.usda"
    bad.write_text("#usda 1.0\n(\n  this is not usd\n")
    with pytest.raises(
        InputError, match=r"garbage.usda: USD could not read it \(.*garbage.usda:3:3: Expected \)"
    ):
        load_usd(bad, "garbage")
    # one time sample far away: the clip would last 1e6 / 30 s
    long = text.replace("30: [(0.70710677, 0, 0, 0.70710677)],", "1000000: [(0.70710677, 0, 0, 0.70710677)],")
    assert long != text
    path.write_text(long)
    with pytest.raises(InputError, match="lasts 33,333.3 s, over the import limit of 600 s"):
        load_usd(path, "long")
    assert capfd.readouterr().err == ""


def test_texture_outside_the_folder_is_not_read(tmp_path):
    """A UsdUVTexture naming a file outside the USD file's folder is ignored, as for glTF."""
    import numpy as np
    from PIL import Image

    from zooctl.io.usd_export import save_usd

    asset = load_gltf(write_tiny_glb(tmp_path / "tiny.glb"), "tiny")
    asset.uvs = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32)
    import io

    buf = io.BytesIO()
    Image.new("RGB", (2, 2), (0, 200, 0)).save(buf, format="PNG")
    asset.texture_png = buf.getvalue()
    (tmp_path / "m").mkdir()
    save_usd(asset, tmp_path / "m" / "t.usda")
    assert load_usd(tmp_path / "m" / "t.usda", "t").texture_png is not None
    text = (tmp_path / "m" / "t.usda").read_text()
    pngs = sorted(p.name for p in (tmp_path / "m").rglob("*.png"))
    assert pngs, "the exporter writes the texture beside the file"
    (tmp_path / "secret.png").write_bytes(buf.getvalue())
    import re

    text2 = re.sub(r"@[^@]*\.png@", f"@{tmp_path / 'secret.png'}@", text)
    assert text2 != text
    (tmp_path / "m" / "t.usda").write_text(text2)
    assert load_usd(tmp_path / "m" / "t.usda", "t").texture_png is None


@pytest.mark.parametrize(
    "arc",
    [
        "sublayer-abs",
        "sublayer-up",
        "reference-abs",
        "reference-up",
        "payload-up",
        "variant-payload",
        "symlink-out",
    ],
)
def test_composition_arcs_stay_in_the_files_folder(tiny_usda, tmp_path, arc):
    """Every layer a stage composes must lie in the file's folder (after symlinks): the outside
    layer here holds the whole skinned animal, so importing it would succeed if it were opened."""
    path, _ = tiny_usda
    outside = tmp_path / "outside"
    outside.mkdir()
    path.rename(outside / "tiny.usda")
    folder = tmp_path / "m"
    folder.mkdir()
    far, up = outside / "tiny.usda", "../outside/tiny.usda"
    body = {
        "sublayer-abs": f"(\n    subLayers = [@{far}@]\n)\n",
        "sublayer-up": f"(\n    subLayers = [@{up}@]\n)\n",
        "reference-abs": f'def "A" (\n    prepend references = @{far}@\n)\n{{\n}}\n',
        "reference-up": f'def "A" (\n    references = @{up}@\n)\n{{\n}}\n',
        "payload-up": f'def "A" (\n    payload = @{up}@\n)\n{{\n}}\n',
        "variant-payload": (
            'def "A" (\n    variants = {\n        string v = "x"\n    }\n    prepend variantSets = "v"\n)\n'
            f'{{\n    variantSet "v" = {{\n        "x" (\n            payload = @{up}@\n        ) {{\n        }}\n    }}\n}}\n'
        ),
        "symlink-out": "(\n    subLayers = [@./inside.usda@]\n)\n",
    }[arc]
    if arc == "symlink-out":
        (folder / "inside.usda").symlink_to(far)
    main = folder / f"main_{arc.replace('-', '_')}.usda"
    main.write_text("#usda 1.0\n" + body)
    with pytest.raises(InputError, match="outside the file's folder"):
        load_usd(main, "m")
    from cli_helpers import zooctl

    r = zooctl("bank", "add", str(main), store=tmp_path / "store")
    assert r.code == 2 and "outside the file's folder" in r.err and "Traceback" not in r.err, r.err


def test_arcs_inside_the_folder_still_compose(tiny_usda):
    path, _ = tiny_usda
    (path.parent / "sub").mkdir()
    path.rename(path.parent / "sub" / "tiny.usda")
    main = path.parent / "main_in.usda"
    main.write_text("#usda 1.0\n(\n    subLayers = [@./sub/tiny.usda@]\n)\n")
    assert load_usd(main, "ok").vertices.shape[0] > 0
