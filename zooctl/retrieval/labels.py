"""What animal each bank asset is: its label (`zooctl.retrieval.taxonomy` reads it).

In order: the label a user gives (`bank add --label`, `bank label NAME LABEL`); else the animal its
name or tags name ("horse_walk.glb", ``--tag wolf``); else its rendered retrieval views classified
by the shipped EfficientNet-Lite0's ImageNet head (`zooctl.retrieval.semantic.views_taxon`). An
asset none of them names stays unlabelled: search still ranks it by appearance.
Sources recorded with the label: ``given``, ``name``, ``tags``, ``views``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import UsageError
from .taxonomy import Taxon, load_taxonomy


def check_label(label: str) -> Taxon:
    """The taxon a user's label names, or a `UsageError` saying what to give instead."""
    taxon = load_taxonomy().resolve(label) if label and label.strip() else None
    if taxon is None:
        raise UsageError(
            f"{label!r} names no animal zooctl knows",
            hint="give a common English name ('red fox', 'horse', 'mallard') or a body plan "
            "(quadruped, bird, fish, snake, insect, spider, crab, humanoid)",
        )
    return taxon


def name_label(name: str, tags: list[str] | tuple[str, ...] = ()) -> tuple[Taxon, str] | None:
    """(taxon, "name" or "tags") of the animal an asset's name or tags name, or None."""
    tax = load_taxonomy()
    from_name = tax.find(name)
    taxon = tax.infer(name, list(tags))
    if taxon is None:
        return None
    return taxon, ("name" if taxon == from_name else "tags")


def label_asset(asset, label: str | None = None) -> None:
    """Set ``asset.meta``'s label before it is stored: ``label`` (checked) when given, else one
    its name or tags name; an asset already labelled keeps its label."""
    if label is not None:
        check_label(label)
        asset.meta["label"], asset.meta["label_source"] = label.strip(), "given"
        return
    if isinstance(asset.meta.get("label"), str):
        return
    found = name_label(asset.name, asset.meta.get("tags", []))
    if found is not None:
        asset.meta["label"], asset.meta["label_source"] = found[0].name, found[1]


def label_from_views(bank, name: str, classes: np.ndarray | None) -> dict[str, Any] | None:
    """Label a stored, unlabelled asset (one of a bank made before labels, when `bank reindex`
    renders it): from its name or tags, else its views' ImageNet probabilities. Returns its new
    index entry, or None when it has a label already or nothing names an animal."""
    from .semantic import views_taxon

    entry = bank.summary(name)
    if isinstance(entry.get("label"), str):
        return None
    found = name_label(name, entry.get("tags", []))
    if found is not None:
        return bank.set_label(name, found[0].name, found[1])
    taxon = None if classes is None else views_taxon(classes)
    return None if taxon is None else bank.set_label(name, taxon.name, "views")


def classify_stored_views(bank, name: str, device: str = "cpu") -> np.ndarray | None:
    """(1000,) mean ImageNet probabilities of an asset's stored views, or None without views."""
    from ..errors import StoreError
    from ..store import views_h5
    from .embedder_cache import cached_embedder

    try:
        sv = views_h5.read_views(views_h5.views_path(bank.root, name), images=True, embedders=[])
    except StoreError:
        return None
    if sv.images is None or len(sv.images) == 0:
        return None
    return cached_embedder("effnet", device).classify(sv.images).mean(0)


def relabel(bank, name: str, label: str | None = None, device: str = "cpu") -> dict[str, Any] | None:
    """`bank label`: set ``label`` (checked), or infer one again from the asset's name, tags and
    stored views. Returns the new index entry, or None when nothing names an animal."""
    if label is not None:
        check_label(label)
        return bank.set_label(name, label.strip(), "given")
    entry = bank.summary(name)
    found = name_label(name, entry.get("tags", []))
    if found is not None:
        return bank.set_label(name, found[0].name, found[1])
    from .semantic import views_taxon

    classes = classify_stored_views(bank, name, device)
    taxon = None if classes is None else views_taxon(classes)
    return None if taxon is None else bank.set_label(name, taxon.name, "views")
