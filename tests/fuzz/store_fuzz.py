"""Damaged-store fuzzing: a base store built once from the shared assets, damaged store states
generated from it with a fixed seed, and a runner that puts the usual commands to each state.

Each state is a copy of the base store with one or two damages (deleted, truncated or garbage
indexes, index entries missing fields, damaged asset files, cards, view sidecars, packs, video
files and query caches, stale temporaries, unreadable files, read-only folders, HDF5 files and
indexes declaring gigabytes they do not hold, FIFOs, sockets and links to /dev/zero). The commands of
`COMMANDS` run in one child process per state (in-process `zooctl.cli.main.run`, so a state costs
one interpreter start); the parent kills a child that runs past 60 s a command. A state passes when

- every command ends in success or in one clear ``error:`` line (exit 1 or 2; no traceback, no
  "internal failure", no crash), within 60 s and 2 GB;
- every stored item file the damage did not touch (asset files, cards, view sidecars, video
  files) is byte-identical afterwards, except the one `bank rm` removes;
- after a successful `bank repair` / `video repair`, the bank and the videos list every item whose
  files were not damaged (nothing is lost from the index).

Used by ``tests/fuzz/test_store_fuzz.py`` (a quick subset) and ``bench/fuzz_store.py`` (the full run).
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
HANG_S = 60.0
MAX_RSS_KB = 2 * 1024 * 1024  # one command's peak, with the default read limits
VIDEO = "clip"
VICTIM_INDEX = -1  # `bank rm` removes the last asset of the base store
NEW_NAME = "fuzznew"

# Root ignores file permissions; without these capabilities it honours them like any user.
NO_OVERRIDE = (
    ["setpriv", "--bounding-set", "-dac_override,-dac_read_search"]
    if os.geteuid() == 0 and shutil.which("setpriv")
    else []
)
PERMISSIONS_APPLY = os.geteuid() != 0 or bool(NO_OVERRIDE)


# -- the base store ----------------------------------------------------------------------------------


def build_base(root: Path, assets: list[Path], video_dir: Path | None, views: int = 2) -> dict:
    """Add ``assets`` (the first ``views`` with silhouette retrieval views), one short video, and
    run one search so packs and the query cache exist. Returns {"assets": [...], "video": bool}."""
    from zooctl.pipelines.bank_import import add_files
    from zooctl.store.bank import Bank
    from zooctl.store.videos import VideoStore

    os.environ["ZOOCTL_EMBEDDERS"] = "silhouette"
    bank = Bank(root)
    names = []
    for i, p in enumerate(assets):
        (r,) = add_files(bank, [p], views=i < views)
        if r.error is not None:
            raise RuntimeError(f"base store: {p}: {r.error.message}")
        names.append(r.name)
    has_video = False
    if video_dir is not None:
        from zooctl.video.ingest import AddOptions, add_video

        add_video(VideoStore(root), video_dir, AddOptions(name=VIDEO, max_frames=6, max_size=160))
        has_video = True
        from zooctl.retrieval.search import search_source

        search_source(bank, VIDEO, ["silhouette"], top=3, frames=4, store_root=root)
    return {"assets": names, "video": has_video}


# -- damages ---------------------------------------------------------------------------------------


@dataclass
class State:
    """One damaged store: what was done, and the files it touched (no longer protected)."""

    seed: int
    kinds: list[str] = field(default_factory=list)
    touched: set[str] = field(default_factory=set)
    readonly: bool = False  # needs permissions to apply (skipped where they cannot)
    outside: dict[str, bytes | None] = field(
        default_factory=dict
    )  # files beyond the store, as they must stay


def _asset_files(base: dict, name: str) -> list[str]:
    return [f"bank/assets/{name}.h5", f"bank/assets/{name}.json", f"bank/views/{name}.h5"]


def _garbage(rng: random.Random, n: int) -> bytes:
    return bytes(rng.getrandbits(8) for _ in range(n))


def _truncate(p: Path, rng: random.Random) -> None:
    data = p.read_bytes()
    p.write_bytes(data[: rng.randrange(0, max(1, len(data)))])


def _scribble(p: Path, rng: random.Random) -> None:
    """Overwrite a random stretch of the file with random bytes."""
    data = bytearray(p.read_bytes())
    if not data:
        return
    start = rng.randrange(len(data))
    n = rng.randint(1, max(1, min(4096, len(data) - start)))
    data[start : start + n] = _garbage(rng, n)
    p.write_bytes(bytes(data))


def _damage_file(p: Path, rng: random.Random) -> str:
    how = rng.choice(["delete", "truncate", "empty", "garbage", "scribble"])
    if how == "delete":
        p.unlink()
    elif how == "truncate":
        _truncate(p, rng)
    elif how == "empty":
        p.write_bytes(b"")
    elif how == "garbage":
        p.write_bytes(_garbage(rng, rng.randint(1, 5000)))
    else:
        _scribble(p, rng)
    return how


INDEX_TEXTS = [
    "[]",
    "{}",
    "null",
    '"index"',
    '{"schema_version": 1}',
    '{"schema_version": 0, "KEY": {}}',
    '{"schema_version": 2, "KEY": {}}',
    '{"schema_version": "1", "KEY": {}}',
    '{"schema_version": 1, "KEY": []}',
    '{"schema_version": 1, "KEY": null}',
    "[" * 100000,
]


def _damage_index(root: Path, rel: str, key: str, rng: random.Random) -> str:
    p = root / rel
    data = json.loads(p.read_text())
    how = rng.choice(
        [
            "delete",
            "file",
            "file",
            "text",
            "text",
            "field",
            "type",
            "entry",
            "rename",
            "ghost",
            "drop",
            "directory",
            "fifo",
        ]
    )
    entries = data[key]
    name = rng.choice(sorted(entries)) if entries else None
    if how == "delete":  # the damage of issue 18: once read as an empty store
        p.unlink()
        return "index deleted"
    if how == "file":
        return "index " + _damage_file(p, rng)
    if how == "text":
        p.write_text(rng.choice(INDEX_TEXTS).replace("KEY", key))
        return "index text"
    if how == "directory":
        p.unlink()
        p.mkdir()
        return "index is a folder"
    if how == "fifo":  # reading it would block forever
        p.unlink()
        os.mkfifo(p)
        return "index is a FIFO"
    if name is None:
        p.unlink()
        return "index deleted"
    if how == "field":
        del entries[name][rng.choice(sorted(entries[name]))]
    elif how == "type":
        entries[name][rng.choice(sorted(entries[name]))] = rng.choice([None, "x", -1, [], {}, 1.5, True])
    elif how == "entry":
        entries[name] = rng.choice([None, "x", 3, []])
    elif how == "rename":
        entries[name]["name"] = name + "_other"
    elif how == "ghost":  # an entry whose files do not exist
        entries["ghost"] = dict(entries[name], name="ghost")
    elif how == "drop":  # a stored item the index does not name
        del entries[name]
    p.write_text(json.dumps(data))
    return f"index entry {how}"


def _stale_temps(root: Path, rng: random.Random) -> str:
    dead = 999_999_999  # above any pid_max: a writer that is gone
    for d in ("bank/assets", "bank/views", "bank", "videos"):
        if (root / d).is_dir():
            (root / d / f".x.h5.{dead}.{rng.randrange(10**6)}.tmp").write_bytes(_garbage(rng, 100))
    (root / "bank/assets" / f".live.h5.{os.getpid()}.x.tmp").write_bytes(b"in progress")
    return "stale temporaries (and a live writer's)"


def make_state(base_root: Path, base: dict, root: Path, seed: int, kind: str) -> State:
    """Copy the base store to ``root`` and damage it (``kind``: one of `KINDS`, or "mixed")."""
    shutil.copytree(base_root, root, symlinks=True)
    rng = random.Random(seed)
    st = State(seed)
    for k in [rng.choice(KINDS[:-1]), rng.choice(KINDS[:-1])] if kind == "mixed" else [kind]:
        st.kinds.append(DAMAGES[k](root, base, rng, st))
    return st


def _d_bank_index(root, base, rng, st):
    st.touched.add("bank/index.json")
    return "bank " + _damage_index(root, "bank/index.json", "assets", rng)


def _d_video_index(root, base, rng, st):
    if not base["video"]:
        return _d_bank_index(root, base, rng, st)
    st.touched.add("videos/index.json")
    return "video " + _damage_index(root, "videos/index.json", "videos", rng)


def _d_asset(root, base, rng, st):
    """Damage one of an asset's files: the HDF5 file, its card, or its views sidecar."""
    name = rng.choice(base["assets"])
    rel = rng.choice([r for r in _asset_files(base, name) if (root / r).exists()])
    st.touched.add(rel)
    return f"{rel} {_damage_file(root / rel, rng)}"


def _d_swap(root, base, rng, st):
    a, b = rng.sample(base["assets"], 2)
    shutil.copyfile(root / f"bank/assets/{a}.h5", root / f"bank/assets/{b}.h5")
    st.touched.add(f"bank/assets/{b}.h5")
    return f"asset file of {b} holds {a}"


def _d_unindexed(root, base, rng, st):
    a = rng.choice(base["assets"])
    shutil.copyfile(root / f"bank/assets/{a}.h5", root / "bank/assets/stray.h5")
    (root / "bank/assets/orphan.json").write_text("{}")
    return "an unindexed asset file and an orphan card"


def _d_pack(root, base, rng, st):
    packs = sorted((root / "bank/views").glob("pack-*"))
    if not packs:
        return _d_asset(root, base, rng, st)
    p = rng.choice(packs)
    if p.suffix == ".json" and rng.random() < 0.5:
        a = base["assets"][0]
        p.write_text(json.dumps({"schema_version": 1, "files": {"emb": f"../assets/{a}.h5", "mean": "x"}}))
        return "pack names an asset file"
    return f"{p.name} {_damage_file(p, rng)}"


def _d_video(root, base, rng, st):
    if not base["video"]:
        return _d_asset(root, base, rng, st)
    caches = sorted((root / "videos").glob("*.cache/*"))
    p = rng.choice([root / f"videos/{VIDEO}.h5"] + caches)
    st.touched.add(f"videos/{VIDEO}.h5")
    return f"{p.relative_to(root)} {_damage_file(p, rng)}"


def _d_unreadable(root, base, rng, st):
    options = ["bank/index.json"] + [f"bank/assets/{a}.{e}" for a in base["assets"] for e in ("h5", "json")]
    if base["video"]:
        options += ["videos/index.json", f"videos/{VIDEO}.h5"]
    rel = rng.choice(options)
    (root / rel).chmod(0)
    st.readonly = True
    st.touched.add(rel)
    return f"{rel} unreadable"


def _d_readonly(root, base, rng, st):
    rel = rng.choice(["", "", "bank", "bank/assets", "bank/views", "videos"])
    if rel == "":  # the whole store, as `chmod -R a-w`
        for p in [root, *root.rglob("*")]:
            p.chmod(0o555 if p.is_dir() else 0o444)
    elif (root / rel).is_dir():
        (root / rel).chmod(0o555)
    st.readonly = True
    return f"{rel or 'the whole store'} read-only"


def _d_lock(root, base, rng, st):
    how = rng.choice(["garbage", "folder", "symlink", "dangling symlink", "fifo"])
    lock = root / ".lock"
    lock.unlink(missing_ok=True)
    if how == "folder":
        lock.mkdir()
    elif how == "fifo":
        os.mkfifo(lock)
    elif how.endswith("symlink"):  # writing through it would empty, overwrite or create its target
        target = root.parent / f"outside-{st.seed}.txt"
        if how == "symlink":
            target.write_bytes(b"a file of the user's, outside the store")
        st.outside[str(target)] = target.read_bytes() if target.exists() else None
        lock.symlink_to(target)
    else:
        lock.write_bytes(_garbage(rng, 200))
    return f"lock file {how}"


def _declare_huge(path: Path, key: str, shape: tuple[int, ...], dtype: str = "f4", **kw) -> None:
    """Replace dataset ``key`` of an HDF5 file with one that declares ``shape`` but stores
    nothing (unwritten chunks): a small file that reads as gigabytes."""
    import h5py

    with h5py.File(path, "r+") as f:
        if key in f:
            del f[key]
        if "external" in kw:
            f.create_dataset(key, shape=shape, dtype=dtype, **kw)
        else:
            f.create_dataset(key, shape=shape, dtype=dtype, chunks=(1, *shape[1:]))


def _sparse(p: Path, size: int) -> None:
    with open(p, "r+b" if p.exists() else "wb") as f:
        f.truncate(size)  # holes: no disk, and gigabytes to whoever reads it whole


def _d_bomb(root, base, rng, st):
    """A file whose declared size is a memory bomb: an HDF5 dataset's shape, a sparse index."""
    a = rng.choice(base["assets"])
    options = ["asset_vertices", "asset_clip", "asset_external", "views_embeddings", "bank_index"]
    if base["video"]:
        options += ["video_masks", "video_flow", "video_index"]
    how = rng.choice(options)
    if how.startswith("asset_"):
        rel = f"bank/assets/{a}.h5"
        if how == "asset_vertices":
            _declare_huge(root / rel, "mesh/vertices", (300_000_000, 3))
        elif how == "asset_clip":
            _declare_huge(root / rel, "clips/0/rotations", (2_000_000, 200, 4))
        else:  # data in another file: /etc/passwd read as vertices
            _declare_huge(root / rel, "mesh/vertices", (4, 3), external=[("/etc/passwd", 0, 48)])
    elif how == "views_embeddings":
        rel = f"bank/views/{base['assets'][0]}.h5"
        _declare_huge(root / rel, "embeddings/silhouette", (50_000_000, 512), "f2")
    elif how == "video_masks":
        rel = f"videos/{VIDEO}.h5"
        _declare_huge(root / rel, "masks", (20000, 480, 854), "u1")
    elif how == "video_flow":
        rel = f"videos/{VIDEO}.h5"
        _declare_huge(root / rel, "flow/forward", (20000, 480, 854, 2), "f2")
    else:
        rel = "bank/index.json" if how == "bank_index" else "videos/index.json"
        _sparse(root / rel, 4 * 1024**3)
    st.touched.add(rel)
    return f"{rel}: {how.replace('_', ' ')} declared huge"


def _d_special(root, base, rng, st):
    """A stored file replaced by a FIFO, a socket or a link to /dev/zero: readers must not block."""
    import socket

    options = ["bank/index.json"] + [r for a in base["assets"] for r in _asset_files(base, a)]
    if base["video"]:
        options += ["videos/index.json", f"videos/{VIDEO}.h5"]
    rel = rng.choice([r for r in options if (root / r).exists()])
    p = root / rel
    p.unlink()
    how = rng.choice(["fifo", "socket", "dev_zero"])
    if how == "socket" and len(str(p)) < 100:
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(p))
        s.close()
    elif how == "dev_zero":
        p.symlink_to("/dev/zero")
    else:
        how = "fifo"
        os.mkfifo(p)
    st.touched.add(rel)
    return f"{rel} is a {how}"


class _Payload:
    """Unpickled, this creates ``marker``: what a crafted store file would run."""

    def __init__(self, marker: str):
        self.marker = marker

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def _d_pickle(root, base, rng, st):
    """A pickle that runs code where the store keeps numpy data (the query cache) or where a
    file is read as weights: the marker folder beside the store must never appear."""
    import pickle

    marker = root.parent / f"pwned-{st.seed}"
    st.outside[str(marker)] = None
    payload = pickle.dumps({"emb": _Payload(str(marker))}, protocol=2)
    caches = sorted((root / "videos").glob("*.cache/*"))
    if not caches:
        return _d_asset(root, base, rng, st)
    p = rng.choice(caches)
    p.write_bytes(payload)
    return f"{p.relative_to(root)} a pickle that runs code"


DAMAGES: dict[str, Callable] = {
    "bank-index": _d_bank_index,
    "video-index": _d_video_index,
    "asset": _d_asset,
    "swap": _d_swap,
    "unindexed": _d_unindexed,
    "pack": _d_pack,
    "video": _d_video,
    "temps": lambda root, base, rng, st: _stale_temps(root, rng),
    "unreadable": _d_unreadable,
    "readonly": _d_readonly,
    "lock": _d_lock,
    "bomb": _d_bomb,
    "special": _d_special,
    "pickle": _d_pickle,
}
KINDS = [*DAMAGES, "mixed"]


def plan(n: int, seed: int) -> list[tuple[int, str]]:
    """``n`` (state seed, kind) pairs: every kind in turn, weighted toward the indexes and files."""
    weights = {"bank-index": 3, "video-index": 2, "asset": 3, "video": 2, "mixed": 2}
    cycle = [k for k in KINDS for _ in range(weights.get(k, 1))]
    rng = random.Random(seed)
    return [(rng.randrange(2**31), cycle[i % len(cycle)]) for i in range(n)]


# -- running ---------------------------------------------------------------------------------------


def commands(base: dict, asset_file: Path) -> list[list[str]]:
    first = base["assets"][0]
    victim = base["assets"][VICTIM_INDEX]
    cmds = [["bank", "list"], ["bank", "list", "--json"], ["bank", "show", first, "--json"]]
    cmds += [["bank", "show", a] for a in base["assets"][1:]]
    if base["video"]:
        cmds += [
            ["bank", "search", VIDEO, "--embedder", "silhouette", "--frames", "4", "--top", "3"],
            ["video", "list"],
            ["video", "show", VIDEO, "--json"],
        ]
    cmds += [
        ["bank", "add", str(asset_file), "--name", NEW_NAME, "--no-views"],
        ["bank", "rm", victim],
        ["bank", "clean"],
        ["bank", "migrate"],
        ["bank", "repair"],
        ["bank", "list", "--json"],
    ]
    if base["video"]:
        cmds += [["video", "clean"], ["video", "repair"], ["video", "list", "--json"]]
    return cmds


DRIVER = r"""
import contextlib, io, json, sys, time
from zooctl.cli.main import run
store, cmds = sys.argv[1], json.loads(sys.argv[2])
def peak_kb():
    with open("/proc/self/status") as f:
        return next((int(ln.split()[1]) for ln in f if ln.startswith("VmHWM:")), 0)
for args in cmds:
    print("START", json.dumps(args), flush=True)
    out, err = io.StringIO(), io.StringIO()
    try:  # restart the peak-RSS count: each command's own peak
        open("/proc/self/clear_refs", "w").write("5")
    except OSError:
        pass
    t = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = run(["--store", store, *args])
    res = {"args": args, "code": code, "s": round(time.perf_counter() - t, 3), "err": err.getvalue()}
    res["peak_kb"] = peak_kb()
    if args[-1] == "--json" and code == 0:
        res["json"] = json.loads(out.getvalue())
    print("DONE", json.dumps(res), flush=True)
"""


def _drive(argv: list[str], env: dict, cwd: Path) -> tuple[list[str], str | None, str | None]:
    """Run the driver, killing it when one command runs past `HANG_S`. Returns its stdout lines,
    a crash description (or None) and the command that hung (or None)."""
    import queue
    import tempfile
    import threading

    lines: queue.Queue = queue.Queue()
    with tempfile.TemporaryFile("w+") as errf:
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=errf, text=True, env=env, cwd=cwd)
        reader = threading.Thread(target=lambda: [lines.put(x) for x in proc.stdout] + [lines.put(None)])
        reader.start()
        out, current, hung = [], "startup", None
        while True:
            try:
                ln = lines.get(timeout=HANG_S)
            except queue.Empty:
                hung = current
                proc.kill()
                break
            if ln is None:
                break
            out.append(ln.rstrip("\n"))
            if ln.startswith("START "):
                current = ln[6:].strip()
        proc.wait()
        reader.join()
        errf.seek(0)
        tail = errf.read()[-300:]
    crash = None
    if hung is None and proc.returncode != 0:
        crash = f"crash ({proc.returncode}) during {current}: {tail}"
    return out, crash, hung


def hashes(root: Path, rels: list[str]) -> dict[str, str | None]:
    out = {}
    for rel in rels:
        try:
            out[rel] = hashlib.sha256((root / rel).read_bytes()).hexdigest()
        except FileNotFoundError:
            out[rel] = None
    return out


def protected(base: dict, st: State) -> list[str]:
    """Stored item files the damage did not touch and no command may change."""
    victim = base["assets"][VICTIM_INDEX]
    rels = [r for a in base["assets"] if a != victim for r in _asset_files(base, a)]
    if base["video"]:
        rels.append(f"videos/{VIDEO}.h5")
    return [r for r in rels if r not in st.touched]


def check_output(res: dict) -> str | None:
    """What is wrong with one command's outcome (None: success or one clear error)."""
    err = res["err"]
    if "Traceback" in err or "internal failure" in err:
        return "traceback / internal failure: " + err.strip().splitlines()[-1][:200]
    if res["code"] == 0:
        return None
    if res["code"] not in (1, 2):
        return f"exit {res['code']}"
    errors = [ln for ln in err.splitlines() if ln.startswith("error:")]
    if len(errors) != 1:
        return f"{len(errors)} error lines: {err[:200]}"
    return None


def run_state(
    base_root: Path, base: dict, work: Path, seed: int, kind: str, asset_file: Path, code: Path = REPO
) -> dict:
    """Make one damaged state under ``work``, run the commands with the zooctl of checkout
    ``code`` (default: this one), check it; returns its record."""
    root = work / "store"
    st = make_state(base_root, base, root, seed, kind)
    keep = protected(base, st)
    before = hashes(root, keep)
    cmds = commands(base, asset_file)
    env = {
        **os.environ,
        "PYTHONPATH": str(code),
        "NO_COLOR": "1",
        "COLUMNS": "200",
        "ZOOCTL_LOCK_TIMEOUT": "10",
    }
    env.pop("ZOOCTL_DEBUG", None)
    t0 = time.perf_counter()
    rec = {"seed": seed, "kind": kind, "damage": st.kinds, "problems": [], "outcomes": {}}
    out, err, hung = _drive(
        [*NO_OVERRIDE, sys.executable, "-c", DRIVER, str(root), json.dumps(cmds)], env, work
    )
    results = [json.loads(ln[5:]) for ln in out if ln.startswith("DONE ")]
    if hung is not None:
        rec["problems"].append(f"hang: {hung} ran past {HANG_S:g} s")
    elif err is not None:
        rec["problems"].append(err)
    by = {}
    for res in results:
        name = " ".join(res["args"][:2])
        by[" ".join(res["args"])] = res
        problem = check_output(res)
        if problem:
            rec["problems"].append(f"{' '.join(res['args'])}: {problem}")
        if res["s"] > HANG_S:
            rec["problems"].append(f"{name}: took {res['s']} s")
        if res.get("peak_kb", 0) > MAX_RSS_KB:
            rec["problems"].append(f"{' '.join(res['args'])}: peak memory {res['peak_kb'] // 1024} MB")
        rec["outcomes"][" ".join(res["args"])] = "ok" if res["code"] == 0 else "error"
        if res["code"] != 0:
            rec.setdefault("errors", {})[" ".join(res["args"])] = res["err"].strip().splitlines()[0][:300]
    for p in [root, *root.rglob("*")]:  # let the checks and the cleanup read everything again
        try:
            if not p.is_symlink():
                p.chmod(0o755 if p.is_dir() else 0o644)
        except OSError:
            pass
    for path, content in st.outside.items():
        q = Path(path)
        now = (b"<a folder>" if q.is_dir() else q.read_bytes()) if q.exists() else None
        if now != content:
            rec["problems"].append(f"a path outside the store was written or created: {path}")
    after = hashes(root, keep)
    changed = [r for r in keep if before[r] != after[r]]
    if changed:
        rec["problems"].append(f"changed or lost stored files: {changed}")
    _check_nothing_lost(rec, by, base, st)
    rec["seconds"] = round(time.perf_counter() - t0, 2)
    return rec


def _check_nothing_lost(rec: dict, by: dict, base: dict, st: State) -> None:
    """After a successful repair, every item whose files were not damaged is listed."""
    victim = base["assets"][VICTIM_INDEX]
    repaired = by.get("bank repair", {}).get("code") == 0
    listed = by.get("bank list --json", {}).get("json")  # the last one: after repair
    if repaired and listed is not None:
        want = {a for a in base["assets"] if a != victim and f"bank/assets/{a}.h5" not in st.touched}
        missing = want - {a["name"] for a in listed}
        if missing:
            rec["problems"].append(f"lost from the bank after repair: {sorted(missing)}")
    if base["video"] and by.get("video repair", {}).get("code") == 0:
        vids = by.get("video list --json", {}).get("json")
        if (
            vids is not None
            and f"videos/{VIDEO}.h5" not in st.touched
            and VIDEO not in {v["name"] for v in vids}
        ):
            rec["problems"].append("lost from the videos after repair")


def summarize(records: list[dict]) -> dict:
    """Counts for BENCHMARKS.md: states, commands, successes, clear errors, problems."""
    outcomes = [o for r in records for o in r["outcomes"].values()]
    return {
        "states": len(records),
        "commands": len(outcomes),
        "ok": outcomes.count("ok"),
        "clear_errors": outcomes.count("error"),
        "failed_states": sum(bool(r["problems"]) for r in records),
        "kinds": sorted({r["kind"] for r in records}),
    }
