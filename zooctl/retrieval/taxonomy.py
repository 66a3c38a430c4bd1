"""The animal taxonomy (``taxonomy.json`` beside this module, schema ``schemas/taxonomy.schema.json``):
body plan > order > family > species, the English names people give animals and their files, and
ImageNet-1k's 398 animal classes (indices 0-397) mapped to species.

`Taxonomy.lookup` reads a label ("red fox", "Shiba Inu", "horses"); `Taxonomy.find` finds the
animal a file or asset name mentions ("horse_walk.glb", "ShibaInu", "Fish1"). `agreement` says how
alike two taxa are as templates: 4 same species, 3 same family, 2 same order, 1 same body plan only,
0 different body plans (a body plan is the top of the tree, so nothing agrees across it).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

RANKS = ("body plan", "order", "family", "species")
LEVELS = {"species": 4, "family": 3, "order": 2, "body plan": 1}
ANIMAL_CLASSES = 398  # ImageNet-1k indices 0..397 are animals
DATA = Path(__file__).with_name("taxonomy.json")
_IRREGULAR = {
    "geese": "goose",
    "mice": "mouse",
    "oxen": "ox",
    "teeth": "tooth",
    "people": "person",
    "feet": "foot",
}


@dataclass(frozen=True)
class Taxon:
    """A node of the taxonomy: its ``rank`` (one of `RANKS`), ``name``, and the names of the nodes
    above it (None above a body plan). ``body_plan`` is always set."""

    rank: str
    name: str
    body_plan: str
    order: str | None = None
    family: str | None = None
    species: str | None = None

    def lineage(self) -> str:
        """ "red fox > Canidae > Carnivora > quadruped" (this node first)."""
        parts = [self.species, self.family, self.order, self.body_plan]
        return " > ".join(p for p in parts if p)


def agreement(a: Taxon, b: Taxon) -> int:
    """How alike two taxa are: 4 same species, 3 family, 2 order, 1 body plan, 0 none (see module)."""
    if a.body_plan != b.body_plan:
        return 0
    for rank, level in (("species", 4), ("family", 3), ("order", 2)):
        x, y = getattr(a, rank), getattr(b, rank)
        if x is not None and x == y:
            return level
    return 1


def shared_taxon(a: Taxon, b: Taxon) -> tuple[str, str] | None:
    """(rank, name) of the deepest taxon ``a`` and ``b`` share, or None."""
    level = agreement(a, b)
    if level == 0:
        return None
    rank = {4: "species", 3: "family", 2: "order", 1: "body plan"}[level]
    return rank, (a.body_plan if rank == "body plan" else getattr(a, rank.replace(" ", "_")))


def tokens(text: str) -> list[str]:
    """Lower-case words of a name: a file suffix dropped, camelCase, underscores, digits split."""
    s = str(text).strip()
    s = re.sub(r"\.[A-Za-z][A-Za-z0-9]{0,4}$", "", s)  # "horse_walk.glb"
    s = re.sub(r"(?<=[a-z])(?=[A-Z])", " ", s)  # "ShibaInu"
    s = re.sub(r"(?<=[A-Z])(?=[A-Z][a-z])", " ", s)  # "TRex"
    return re.findall(r"[a-z]+", s.lower())


def singulars(word: str) -> list[str]:
    """Candidate singulars of an English word, most likely first ("wolves" -> wolf, wolfe ...)."""
    out = [_IRREGULAR[word]] if word in _IRREGULAR else []
    if word.endswith("ies") and len(word) > 4:
        out.append(word[:-3] + "y")
    if word.endswith("ves") and len(word) > 4:
        out += [word[:-3] + "f", word[:-3] + "fe"]
    if word.endswith("es") and len(word) > 3:
        out.append(word[:-2])
    if word.endswith("s") and not word.endswith("ss") and len(word) > 3:
        out.append(word[:-1])
    return out


class Taxonomy:
    """The taxonomy loaded from ``taxonomy.json`` (see the module docstring)."""

    def __init__(self, data: dict):
        self.data = data
        self.nodes: dict[tuple[str, str], Taxon] = {}
        self.names: dict[str, Taxon] = {}
        self.squashed: dict[str, Taxon] = {}
        self.weak = {" ".join(tokens(n)) for n in data.get("weak_names", [])}
        orders, families = data["orders"], data["families"]
        for plan, names in data["body_plans"].items():
            self._add(Taxon("body plan", plan, plan), [plan, *names])
        for order, o in orders.items():
            self._add(Taxon("order", order, o["body_plan"], order), [order, *o["names"]])
        for fam, f in families.items():
            plan = f.get("body_plan", orders[f["order"]]["body_plan"])
            self._add(Taxon("family", fam, plan, f["order"], fam), [fam, *f["names"]])
        species: dict[str, tuple[str, list[str]]] = {}
        self.classes: list[str] = []
        class_species: list[str] = []
        for entry in data["imagenet"]:
            cls, fam = entry[0], entry[1]
            sp = entry[2] if len(entry) > 2 else cls
            species.setdefault(sp, (fam, []))[1].append(cls)
            self.classes.append(cls)
            class_species.append(sp)
        for sp, s in data["species"].items():
            species.setdefault(sp, (s["family"], []))[1].extend(s["names"])
        for sp, (fam, names) in species.items():
            f = self.nodes[("family", fam)]
            self._add(Taxon("species", sp, f.body_plan, f.order, fam, sp), [sp, *names])
        self.imagenet = [self.nodes[("species", sp)] for sp in class_species]

    def _add(self, taxon: Taxon, names: list[str]) -> None:
        self.nodes[(taxon.rank, taxon.name)] = taxon
        for n in names:
            key = " ".join(tokens(n))
            old = self.names.get(key)
            # a name two ranks share (a body plan called "spider", the order Araneae) means the deeper one
            if old is None or LEVELS[taxon.rank] > LEVELS[old.rank]:
                self.names[key] = taxon
                self.squashed[key.replace(" ", "")] = taxon

    def node(self, rank: str, name: str) -> Taxon | None:
        return self.nodes.get((rank, name))

    def _phrase(self, words: list[str]) -> tuple[Taxon, str] | None:
        """The taxon a phrase names, trying its last word's singulars and the words run together."""
        variants = [words] + [[*words[:-1], s] for s in singulars(words[-1])]
        for w in variants:
            key = " ".join(w)
            if key in self.names:
                return self.names[key], key
        for w in variants:
            key = "".join(w)
            if key in self.squashed:
                return self.squashed[key], key
        return None

    def lookup(self, text: str) -> Taxon | None:
        """The taxon ``text`` names as a whole ("red fox", "Foxes", "Shiba_Inu"), else None."""
        words = tokens(text)
        hit = self._phrase(words) if words else None
        return hit[0] if hit else None

    def find(self, text: str) -> Taxon | None:
        """The animal a name mentions anywhere ("horse_walk.glb" -> horse): the longest phrase that
        names one, the deepest rank among equally long ones, then the leftmost. Words that are also
        common words in file names ("fly", "kite") count only when nothing else names an animal."""
        words = tokens(text)
        strong: list[tuple[int, int, int, Taxon]] = []
        weak: list[tuple[int, int, int, Taxon]] = []
        for n in range(min(len(words), 5), 0, -1):
            for i in range(len(words) - n + 1):
                hit = self._phrase(words[i : i + n])
                if hit is None:
                    continue
                taxon, key = hit
                (weak if key in self.weak else strong).append((n, LEVELS[taxon.rank], -i, taxon))
        for hits in (strong, weak):
            if hits:
                return max(hits, key=lambda h: h[:3])[3]
        return None

    def infer(self, name: str, tags: list[str] | tuple[str, ...] = ()) -> Taxon | None:
        """The animal an asset's name or tags name: the deepest rank among them, the name first."""
        found = [t for t in (self.find(x) for x in [name, *tags]) if t is not None]
        if not found:
            return None
        best = max(LEVELS[t.rank] for t in found)
        return next(t for t in found if LEVELS[t.rank] == best)

    def resolve(self, label: str) -> Taxon | None:
        """The taxon of a stored label: the whole label, else an animal it mentions."""
        return self.lookup(label) or self.find(label)


@lru_cache(maxsize=1)
def load_taxonomy(path: str | None = None) -> Taxonomy:
    """The shipped taxonomy (parsed once per process)."""
    return Taxonomy(json.loads(Path(path or DATA).read_text()))
