"""FBX, COLLADA (.dae) and BVH import through the ``assimp`` command-line tool.

The Open Asset Import Library's command (Debian/Ubuntu package ``assimp-utils``) converts the file
to binary glTF in a temporary folder, which the glTF importer then reads; the tool is looked up on
``PATH`` (or ``ZOOCTL_ASSIMP``) each time, so installing it needs no restart. A BVH file has no
mesh: assimp builds a small mesh of one pyramid per bone, skinned to it, so motion capture enters
the bank as a visible, animated skeleton.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from ..asset import RiggedAsset
from ..errors import InputError, MissingDependencyError

SUFFIXES = (".fbx", ".dae", ".bvh")
INSTALL_HINT = "install the assimp command: `apt-get install assimp-utils` (Debian/Ubuntu) or `brew install assimp` (macOS)"
TIMEOUT_S = 600


def assimp_command() -> str | None:
    """Path of the assimp executable (``ZOOCTL_ASSIMP`` overrides the PATH lookup), or None."""
    env = os.environ.get("ZOOCTL_ASSIMP")
    if env:
        return env if Path(env).is_file() and os.access(env, os.X_OK) else None
    return shutil.which("assimp")


def load_with_assimp(path: str | Path, name: str, fps: float = 30.0) -> RiggedAsset:
    """Convert ``path`` to glTF with assimp and import it as a `RiggedAsset` named ``name``."""
    from .gltf_import import load_gltf

    path = Path(path)
    if not path.is_file():
        raise InputError(f"no such file: {path}")
    exe = assimp_command()
    if exe is None:
        raise MissingDependencyError(
            f"importing {path.suffix or 'this'} files needs the `assimp` command, which is not installed",
            hint=INSTALL_HINT,
        )
    with tempfile.TemporaryDirectory(prefix="zooctl-assimp-") as d:
        out = Path(d) / "converted.glb"
        try:
            proc = subprocess.run(
                [exe, "export", str(path.resolve()), str(out), "-fglb2"],
                capture_output=True,
                text=True,
                timeout=TIMEOUT_S,
                cwd=d,
            )
        except subprocess.TimeoutExpired:
            raise InputError(
                f"{path.name}: assimp did not finish converting it within {TIMEOUT_S} s"
            ) from None
        if proc.returncode != 0 or not out.is_file() or out.stat().st_size == 0:
            lines = [
                ln.strip()
                for ln in (proc.stderr + "\n" + proc.stdout).splitlines()
                if ln.strip() and "%" not in ln
            ]
            why = next(
                (ln for ln in reversed(lines) if "ERROR" in ln.upper()),
                lines[-1] if lines else f"exit code {proc.returncode}",
            )
            raise InputError(
                f"{path.name}: assimp could not convert it ({why})",
                hint="check that the file opens in another tool; re-export it as glTF (.glb) if it does",
            )
        try:
            asset = load_gltf(out, name, fps=fps)
        except InputError as exc:
            raise InputError(f"{path.name} (converted by assimp): {exc.message}", hint=exc.hint) from None
    asset.meta["source"] = path.name
    asset.meta.setdefault("import_warnings", [])
    asset.meta["converted_by"] = "assimp"
    return asset
