"""Files from a store or a user are data, never code: a crafted pickle in a fit's state, a motion
prior's weights, an embedder's weights or a CLIP checkpoint is refused with one clear line before
anything in it runs. Each payload would create a marker folder if it were unpickled."""

from __future__ import annotations

import io
import json
import os
import pickle
import zipfile
from pathlib import Path

import pytest
from cli_helpers import run_inprocess

from zooctl.errors import InputError, StoreError


class _Payload:
    """Unpickling this calls ``os.mkdir(marker)``: what an attacker's file would do."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def _payload_bytes(marker: Path) -> bytes:
    return pickle.dumps({"version": 1, "stage": 2, "x": _Payload(marker)}, protocol=2)


def _check(marker: Path) -> None:
    assert not marker.exists(), "the crafted file ran code"


def test_fit_resume_does_not_unpickle_code(store, tmp_path, capsys):
    from zooctl.store.fits import FitStore

    marker = tmp_path / "pwned"
    fits = FitStore(store)
    fits.save_record(
        "t",
        {
            "status": "interrupted",
            "source": "x",
            "template": "tube",
            "frames": 2,
            "image_size": [8, 8],
            "config": {},
            "outputs": {},
        },
    )
    fits.state_path("t").write_bytes(_payload_bytes(marker))
    r = run_inprocess(capsys, "fit", "x", "--name", "t", "--resume")
    _check(marker)
    assert r.code != 0 and "Traceback" not in r.err
    assert "saved state of fit 't'" in r.err and len(r.err.strip().splitlines()) <= 2
    # The same file as a torch zip archive (torch.save's format) is refused too.
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("archive/data.pkl", _payload_bytes(marker))
        z.writestr("archive/version", "3\n")
    fits.state_path("t").write_bytes(buf.getvalue())
    with pytest.raises(StoreError):
        fits.load_state("t")
    _check(marker)


def test_a_real_fit_state_still_loads(store):
    import numpy as np
    import torch

    from zooctl.store.fits import FitStore

    fits = FitStore(store)
    fits.save_record(
        "t",
        {
            "status": "running",
            "source": "x",
            "template": "t",
            "frames": 2,
            "image_size": [8, 8],
            "config": {},
            "outputs": {},
        },
    )
    opt = torch.optim.Adam([torch.nn.Parameter(torch.zeros(3))])
    state = {
        "version": 1,
        "stage": 2,
        "iteration": 4,
        "scene": {"a": torch.ones(2)},
        "optimizer": opt.state_dict(),
        "history": {"stage1": [{"total": 1.0}]},
        "camera_init": {"focal": np.float64(1.0), "views": [np.float32(0.1), None]},
        "config": {"preset": "fast"},
        "timings": {"stage1": 0.5},
    }
    fits.save_state("t", state)
    back = fits.load_state("t")
    assert back["iteration"] == 4 and torch.equal(back["scene"]["a"], torch.ones(2))
    assert back["camera_init"]["focal"] == 1.0  # numpy scalars come back as plain numbers


def test_motion_prior_weights_are_data_only(tmp_path):
    from zooctl.motion.prior import WEIGHTS, PonymationPrior

    marker = tmp_path / "pwned"
    d = tmp_path / "prior"
    d.mkdir()
    (d / "config.json").write_text(json.dumps({"schema_version": _prior_version(), "model": {}, "files": {}}))
    (d / WEIGHTS).write_bytes(_payload_bytes(marker))
    with pytest.raises(StoreError):
        PonymationPrior.load(d)
    _check(marker)


def _prior_version() -> int:
    from zooctl.motion.prior import SCHEMA_VERSION

    return SCHEMA_VERSION


@pytest.mark.parametrize("layout", ["legacy", "zip", "script"])
def test_weights_reader_never_runs_code(tmp_path, layout):
    """The numpy weights reader (effnet's, and the CLIP plugin's TorchScript path) refuses a payload
    wherever torch's formats put a pickle: the legacy stream's header, a zip's data.pkl, and a
    TorchScript archive's data.pkl."""
    from zooctl.embed.state_dict import load_state_dict

    marker = tmp_path / "pwned"
    path = tmp_path / "w.pt"
    if layout == "legacy":
        path.write_bytes(_payload_bytes(marker))  # where the magic number belongs
    else:
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("w/data.pkl", _payload_bytes(marker))
            if layout == "script":
                z.writestr("w/code/__torch__.py", "def f(): pass\n")
    with pytest.raises(InputError):
        load_state_dict(path)
    _check(marker)


def test_a_torchscript_archive_reads_as_its_state_dict(tmp_path):
    """OpenAI's CLIP files are TorchScript archives: their tensors are read without loading code."""
    import torch

    from zooctl.embed.state_dict import load_state_dict

    inner = torch.nn.Sequential(torch.nn.Linear(2, 3), torch.nn.LayerNorm(3))
    traced = torch.jit.trace(inner, torch.zeros(1, 2))
    path = tmp_path / "ts.pt"
    traced.save(str(path))
    got = load_state_dict(path)
    ref = traced.state_dict()
    assert sorted(got) == sorted(ref)
    for k, v in ref.items():
        assert (got[k] == v.numpy()).all()
