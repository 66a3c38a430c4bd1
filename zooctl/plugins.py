"""The one plugin manager: loads every ``zooctl`` entry point and collects what plugins register.

Built-in components live in `zooctl.builtins` and are advertised in zooctl's own
``pyproject.toml`` under ``[project.entry-points.zooctl]``, exactly as a third party would.

``ZOOCTL_LOAD_PLUGINS`` (comma-separated entry-point or distribution names) restricts which
third-party plugins load; an empty value loads none. zooctl's own built-ins always load.
A plugin that fails to import, or whose hook raises, is reported by name and skipped.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

import pluggy

from . import hookspecs
from .components import KINDS, ComponentSpec, ExporterSpec, ImporterSpec
from .errors import NotFoundError, PluginError

GROUP = "zooctl"
hookimpl = pluggy.HookimplMarker("zooctl")

_HOOK_FOR_KIND = {
    "importer": "register_importers",
    "exporter": "register_exporters",
    "embedder": "register_embedders",
    "renderer": "register_renderers",
    "articulation_model": "register_articulation_models",
    "motion_prior": "register_motion_priors",
    "segmenter": "register_segmenters",
    "flow_estimator": "register_flow_estimators",
    "executor": "register_executors",
}


@dataclass
class PluginInfo:
    name: str
    distribution: str
    version: str
    module: str
    builtin: bool
    status: str = "loaded"  # loaded | failed | skipped
    error: str = ""
    registers: dict[str, list[str]] = field(default_factory=dict)
    hooks: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "distribution": self.distribution,
            "version": self.version,
            "module": self.module,
            "builtin": self.builtin,
            "status": self.status,
            "error": self.error,
            "hooks": self.hooks,
            "registers": self.registers,
        }


@dataclass
class Registry:
    """Every registered component by kind and name, and who registered it."""

    components: dict[str, dict[str, Any]] = field(default_factory=lambda: {k: {} for k in KINDS})
    owner: dict[tuple[str, str], str] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    def get(self, kind: str, name: str) -> Any:
        comp = self.components[kind].get(name)
        if comp is None:
            known = ", ".join(sorted(self.components[kind])) or "none"
            raise NotFoundError(
                f"no {kind.replace('_', ' ')} named {name!r}",
                hint=f"available: {known} (see `zooctl plugins`)",
            )
        return comp

    def names(self, kind: str) -> list[str]:
        return sorted(self.components[kind])

    def importer_for(self, suffix: str) -> ImporterSpec | None:
        for spec in self.components["importer"].values():
            if suffix.lower() in spec.suffixes:
                return spec
        return None

    def exporter_for(self, fmt: str) -> ExporterSpec | None:
        for spec in self.components["exporter"].values():
            if fmt.lower() in spec.formats:
                return spec
        return None


class PluginManager:
    def __init__(self) -> None:
        self.pm = pluggy.PluginManager(GROUP)
        self.pm.add_hookspecs(hookspecs)
        self.infos: dict[str, PluginInfo] = {}
        self._registry: Registry | None = None
        self.in_process: set[str] = set()  # registered by `register`: another process lacks them

    # -- loading --------------------------------------------------------------------------
    def load_entry_points(self) -> None:
        allowed = os.environ.get("ZOOCTL_LOAD_PLUGINS")
        allow = None if allowed is None else {s.strip() for s in allowed.split(",") if s.strip()}
        eps = sorted(metadata.entry_points(group=GROUP), key=lambda e: (not _is_builtin(e), e.name))
        for ep in eps:
            dist = ep.dist.metadata["Name"] if ep.dist is not None else "?"
            version = ep.dist.version if ep.dist is not None else "?"
            info = PluginInfo(ep.name, dist, version, ep.value, _is_builtin(ep))
            if ep.name in self.infos:
                continue  # the same distribution seen twice on sys.path
            self.infos[ep.name] = info
            if not info.builtin and allow is not None and ep.name not in allow and dist not in allow:
                info.status = "skipped"
                info.error = "not in ZOOCTL_LOAD_PLUGINS"
                continue
            try:
                module = ep.load()
                self.pm.register(module, name=ep.name)
            except Exception as exc:  # a broken plugin must never take the CLI down
                info.status = "failed"
                info.error = f"{type(exc).__name__}: {exc}"
                continue
            try:
                self.check()
            except PluginError as exc:  # a misspelt hook: report it loudly, keep the rest working
                self.pm.unregister(name=ep.name)
                info.status = "failed"
                info.error = exc.message

    def register(self, plugin: Any, name: str, distribution: str = "(in-process)", version: str = "") -> None:
        """Register a plugin object directly (tests, notebooks, embedding applications)."""
        self.pm.register(plugin, name=name)
        try:
            self.check()
        except PluginError:
            self.pm.unregister(name=name)
            raise
        self.infos[name] = PluginInfo(name, distribution, version, repr(plugin), builtin=False)
        self.in_process.add(name)
        self._registry = None
        self.check()

    def check(self) -> None:
        """Fail loudly on a hook implementation that matches no spec (a misspelt hook name)."""
        try:
            self.pm.check_pending()
        except pluggy.PluginValidationError as exc:
            raise PluginError(str(exc), hint="check the hook's spelling against zooctl.hookspecs") from exc
        for name, info in self.infos.items():
            plugin = self.pm.get_plugin(name)
            if plugin is not None:
                info.hooks = sorted(impl for impl in _hook_names(self.pm, plugin))

    # -- collecting -----------------------------------------------------------------------
    @property
    def registry(self) -> Registry:
        if self._registry is None:
            self._registry = self._collect()
        return self._registry

    def _collect(self) -> Registry:
        reg = Registry()
        for kind, hook_name in _HOOK_FOR_KIND.items():
            caller = getattr(self.pm.hook, hook_name)
            # Call each implementation on its own, so a component is attributed to its plugin
            # and a plugin whose hook raises is reported and skipped, not fatal for all.
            for (
                impl
            ) in caller.get_hookimpls():  # registration order: built-ins first, so they keep their names
                owner = impl.plugin_name

                def register(spec: Any, _owner: str = owner, _kind: str = kind) -> None:
                    _add(reg, self.infos, _kind, spec, _owner)

                try:
                    impl.function(register=register)
                except Exception as exc:
                    info = self.infos.get(owner)
                    msg = f"plugin {owner!r} failed in {hook_name}: {type(exc).__name__}: {exc}"
                    reg.problems.append(msg)
                    if info is not None:
                        info.status = "failed"
                        info.error = msg
        return reg

    def add_commands(self, cli: Any) -> None:
        for impl in self.pm.hook.register_commands.get_hookimpls():
            try:
                impl.function(cli=cli)
            except Exception as exc:
                info = self.infos.get(impl.plugin_name)
                if info is not None:
                    info.status = "failed"
                    info.error = f"register_commands: {type(exc).__name__}: {exc}"

    def failures(self) -> list[PluginInfo]:
        return [i for i in self.infos.values() if i.status == "failed"]


def _add(reg: Registry, infos: dict[str, PluginInfo], kind: str, spec: Any, owner: str) -> None:
    expected = {"importer": ImporterSpec, "exporter": ExporterSpec}.get(kind, ComponentSpec)
    if not isinstance(spec, expected) or spec.kind != kind:
        raise PluginError(
            f"register() in the {kind} hook needs a {expected.__name__} of kind {kind!r}, got {spec!r}"
        )
    if spec.name in reg.components[kind]:
        reg.problems.append(
            f"{kind} {spec.name!r} from plugin {owner!r} ignored: already registered by {reg.owner[(kind, spec.name)]!r}"
        )
        return
    reg.components[kind][spec.name] = spec
    reg.owner[(kind, spec.name)] = owner
    info = infos.get(owner)
    if info is not None:
        info.registers.setdefault(kind, []).append(spec.name)


def _hook_names(pm: pluggy.PluginManager, plugin: Any) -> list[str]:
    return [caller.name for caller in (pm.get_hookcallers(plugin) or [])]


def _is_builtin(ep: metadata.EntryPoint) -> bool:
    return ep.value.startswith("zooctl.builtins")


_MANAGER: PluginManager | None = None


def get_plugin_manager() -> PluginManager:
    """The process-wide plugin manager, loaded on first use."""
    global _MANAGER
    if _MANAGER is None:
        m = PluginManager()
        m.load_entry_points()
        _MANAGER = m
    return _MANAGER


def get_registry() -> Registry:
    return get_plugin_manager().registry


def reset() -> None:
    """Forget the loaded plugins (tests; after installing a plugin in-process)."""
    global _MANAGER
    _MANAGER = None
    metadata_cache_clear()


def metadata_cache_clear() -> None:
    import importlib

    importlib.invalidate_caches()
    if hasattr(sys, "path_importer_cache"):
        sys.path_importer_cache.clear()
