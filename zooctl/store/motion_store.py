"""Trained motion priors in the store: ``<store>/motion/<name>/`` holds ``config.json`` (schema:
``schemas/motion_prior.schema.json``), the weights file it names, and ``loss.png``.

A prior is written whole into a temporary directory beside its final place (every file fsynced),
then published by ``os.replace`` of the directory under the store's writers' lock, so a reader
sees a complete prior or none, and a killed writer leaves only a temporary directory (removed by
the next write). Replacing moves the old directory aside first and deletes it after.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..errors import NotFoundError, StoreError
from ..files import regular_size
from ..names import check_name
from .fs import fsync_dir, pid_alive, read_regular, store_lock, writing
from .indexed import NamedStore

CONFIG = "config.json"


def load_prior_dir(path: Path, device: str = "cpu") -> Any:
    """The prior in folder ``path`` through its plugin (``config["plugin"]``)."""
    try:
        cfg = json.loads(read_regular(Path(path) / CONFIG))
    except (OSError, json.JSONDecodeError) as exc:
        raise StoreError(
            f"{path} holds no readable motion prior: {exc}",
            hint="give a folder made by `zooctl motion train`",
        ) from None
    _check_regular(Path(path))
    return _create(cfg, Path(path), device)


def _check_regular(folder: Path) -> None:
    """Every file of a prior folder is a regular one: its plugin's loader (torch, numpy) would block
    on a FIFO in place of its weights, and read a link to /dev/zero without end."""
    for p in folder.iterdir():
        if p.is_dir():
            continue
        try:
            regular_size(p, "the motion prior file", None, StoreError)
        except FileNotFoundError:  # a dangling link: the loader says what is missing
            continue


def _create(cfg: dict[str, Any], path: Path, device: str) -> Any:
    from ..plugins import get_registry

    spec = get_registry().get("motion_prior", cfg.get("plugin", "ponymation"))
    return spec.create(path=path, device=device)


class MotionStore(NamedStore):
    noun, article, place, list_cmd = "motion prior", "a", "the store", "zooctl motion list"
    exists_hint = "use --replace or another --name"
    folder = "motion"

    def path(self, name: str) -> Path:
        return self.dir / check_name(name, "motion prior name")

    def exists(self, name: str) -> bool:
        return (self.path(name) / CONFIG).is_file()

    def names(self) -> list[str]:
        if not self.dir.is_dir():
            return []
        return sorted(
            p.name for p in self.dir.iterdir() if not p.name.startswith(".") and (p / CONFIG).is_file()
        )

    def config(self, name: str) -> dict[str, Any]:
        p = self.path(name) / CONFIG
        try:
            return json.loads(read_regular(p))
        except FileNotFoundError:
            raise self._not_found(name) from None
        except (OSError, json.JSONDecodeError) as exc:
            raise StoreError(
                f"the config of motion prior {name!r} is unreadable: {exc}", hint="train it again"
            ) from None

    def list(self) -> list[dict[str, Any]]:
        out = []
        for n in self.names():
            try:
                out.append(self.config(n))
            except (StoreError, NotFoundError):
                continue  # removed or replaced while listing
        return out

    def latest(self) -> str:
        """The most recently written prior (the default of `zooctl animate`)."""
        names = self.names()
        if not names:
            raise NotFoundError(
                f"no motion prior in the store at {self.root}", hint="train one: zooctl motion train --all"
            )
        return max(names, key=lambda n: (self.path(n) / CONFIG).stat().st_mtime_ns)

    def load(self, name: str, device: str = "cpu") -> Any:
        """The prior through its plugin (``config["plugin"]``), so third-party priors load too."""
        return _create(self.config(name), self.path(name), device)

    def resolve(self, name: str | None) -> Path:
        """The folder of a prior given by name in this store, by a folder written by `zooctl motion
        train` (a path with its config.json), or None for the latest."""
        if name and (Path(name).expanduser() / CONFIG).is_file():
            return Path(name).expanduser().resolve()
        name = name or self.latest()
        self.config(name)
        return self.path(name).resolve()

    def add(self, name: str, write: Callable[[Path], None], replace: bool = False) -> Path:
        """Publish a prior: ``write(tmpdir)`` fills a temporary directory (must write config.json)."""
        final = self.path(name)
        if not replace and self.exists(name):
            raise self._exists(name)
        with writing(f"adding motion prior {name!r}"):
            self.dir.mkdir(parents=True, exist_ok=True)
            self.cleanup()
            tmp = Path(tempfile.mkdtemp(prefix=f".{name}.{os.getpid()}.", suffix=".tmp", dir=self.dir))
        try:
            with writing(f"writing motion prior {name!r}"):
                write(tmp)
            if not (tmp / CONFIG).is_file():
                raise StoreError(f"motion prior {name!r} was written without {CONFIG}")
            for f in tmp.iterdir():
                fd = os.open(f, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
            fsync_dir(tmp)
            with store_lock(self.root), writing(f"publishing motion prior {name!r}"):
                old = None
                if final.exists():
                    if not replace and (final / CONFIG).is_file():
                        raise self._exists(name)
                    old = self.dir / f".{name}.{os.getpid()}.old.tmp"
                    os.replace(final, old)
                os.replace(tmp, final)
                fsync_dir(self.dir)
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        return final

    def remove(self, name: str) -> None:
        final = self.path(name)
        with store_lock(self.root), writing(f"removing motion prior {name!r}"):
            if not (final / CONFIG).is_file():
                raise self._not_found(name)
            gone = self.dir / f".{name}.{os.getpid()}.rm.tmp"
            os.replace(final, gone)  # invisible at once; deleting the files can take its time
            fsync_dir(self.dir)
        shutil.rmtree(gone, ignore_errors=True)

    def cleanup(self) -> int:
        """Remove temporary directories whose writer process is gone."""
        n = 0
        if not self.dir.is_dir():
            return 0
        for p in self.dir.glob(".*.tmp"):
            pid = next((int(x) for x in p.name.split(".") if x.isdigit()), None)
            if pid is not None and pid_alive(pid):
                continue  # a live writer's work in progress
            shutil.rmtree(p, ignore_errors=True)
            n += 1
        return n

    def _exists(self, name: str):
        return self.exists_error(name)
