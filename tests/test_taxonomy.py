"""The shipped animal taxonomy: valid against its schema, every ImageNet animal class maps to a
species with a family, order and body plan, names are found in labels and file names (plurals,
case, underscores, camelCase, suffixes), and taxonomic agreement ranks species > family > order >
body plan."""

from __future__ import annotations

import json

import jsonschema
import pytest
from cli_helpers import REPO

from zooctl.retrieval.taxonomy import (
    ANIMAL_CLASSES,
    DATA,
    RANKS,
    Taxonomy,
    agreement,
    load_taxonomy,
    shared_taxon,
    tokens,
)


@pytest.fixture(scope="module")
def tax():
    return load_taxonomy()


def test_taxonomy_file_matches_its_schema():
    schema = json.loads((REPO / "schemas" / "taxonomy.schema.json").read_text())
    jsonschema.validate(json.loads(DATA.read_text()), schema)


def test_every_imagenet_animal_class_maps_to_a_full_lineage(tax):
    assert len(tax.imagenet) == len(tax.classes) == ANIMAL_CLASSES
    for i, t in enumerate(tax.imagenet):
        assert t.rank == "species" and t.family and t.order and t.body_plan, (i, t)
        assert tax.node("family", t.family).order == t.order
        assert tax.lookup(tax.classes[i]) == t, tax.classes[i]  # every class name reads back


@pytest.mark.parametrize(
    ("index", "species", "family", "plan"),
    [
        (0, "tench", "Cyprinidae", "fish"),
        (97, "mallard", "Anatidae", "bird"),
        (100, "black swan", "Anatidae", "bird"),
        (207, "domestic dog", "Canidae", "quadruped"),
        (277, "red fox", "Canidae", "quadruped"),
        (294, "brown bear", "Ursidae", "quadruped"),
        (345, "cattle", "Bovidae", "quadruped"),
        (339, "horse", "Equidae", "quadruped"),
        (386, "African elephant", "Elephantidae", "quadruped"),
        (61, "boa constrictor", "Boidae", "snake"),
        (51, "triceratops", "Ceratopsidae", "quadruped dinosaur"),
        (76, "tarantula", "Theraphosidae", "spider"),
        (309, "honeybee", "Apidae", "insect"),
        (397, "puffer", "Tetraodontidae", "fish"),
    ],
)
def test_known_classes(tax, index, species, family, plan):
    t = tax.imagenet[index]
    assert (t.species, t.family, t.body_plan) == (species, family, plan)


@pytest.mark.parametrize(
    ("text", "rank", "name"),
    [
        ("Shiba_Inu", "species", "domestic dog"),
        ("ShibaInu", "species", "domestic dog"),
        ("shibainu", "species", "domestic dog"),
        ("horse_walk.glb", "species", "horse"),
        ("HORSES", "species", "horse"),
        ("wolves", "species", "grey wolf"),
        ("Foxes.fbx", "species", "red fox"),
        ("geese", "species", "goose"),
        ("puppies", "species", "domestic dog"),
        ("red_fox_rig_v2.fbx", "species", "red fox"),
        ("Fish1", "body plan", "fish"),
        ("Manta_ray", "species", "manta ray"),
        ("Trex", "species", "Tyrannosaurus rex"),
        ("TRex", "species", "Tyrannosaurus rex"),
        ("t-rex", "species", "Tyrannosaurus rex"),
        ("Deer", "family", "Cervidae"),
        ("Whale", "order", "Cetacea"),
        ("Spider", "order", "Araneae"),
        ("quadruped-longneck", "body plan", "quadruped"),
        ("dinosaur-duckbill", "family", "Hadrosauridae"),
        ("bird_fly", "body plan", "bird"),  # "fly" is a word in file names: the bird wins
        ("fly", "species", "housefly"),  # ... but alone it is the insect
        ("cow-low-poly", "species", "cattle"),
    ],
)
def test_find_names_in_file_names(tax, text, rank, name):
    t = tax.find(text)
    assert t is not None and (t.rank, t.name) == (rank, name), (text, t)


@pytest.mark.parametrize("text", ["Character", "model_final_v2.glb", "rig", "", "walk_cycle"])
def test_names_without_an_animal(tax, text):
    assert tax.find(text) is None


def test_lookup_reads_a_label_as_a_whole(tax):
    assert tax.lookup("red fox").name == "red fox"
    assert tax.lookup("Red Foxes").name == "red fox"
    assert tax.lookup("fox").name == "red fox"
    assert tax.lookup("red fox walking") is None  # a label is one name; `find` searches in it
    assert tax.resolve("red fox walking").name == "red fox"


def test_infer_takes_the_deepest_of_name_and_tags(tax):
    assert tax.infer("model_03", ["quadruped", "wolf"]).name == "grey wolf"
    assert tax.infer("Wolf", ["quadruped"]).name == "grey wolf"
    assert tax.infer("model_03", ["procedural"]) is None


def test_agreement_ranks_species_family_order_plan(tax):
    fox, wolf, bear = tax.lookup("red fox"), tax.lookup("wolf"), tax.lookup("brown bear")
    cow, swan, quad = tax.lookup("cow"), tax.lookup("black swan"), tax.lookup("quadruped")
    assert agreement(fox, fox) == 4
    assert agreement(fox, wolf) == 3
    assert agreement(fox, bear) == 2
    assert agreement(fox, cow) == 1 and agreement(fox, quad) == 1
    assert agreement(fox, swan) == 0
    assert shared_taxon(fox, wolf) == ("family", "Canidae")
    assert shared_taxon(fox, bear) == ("order", "Carnivora")
    assert shared_taxon(fox, swan) is None
    # snakes and lizards share an order but not a body plan: nothing in common as templates
    assert agreement(tax.lookup("king snake"), tax.lookup("iguana")) == 0


def test_names_are_unambiguous_within_a_rank():
    data = json.loads(DATA.read_text())
    tax = Taxonomy(data)
    seen: dict[str, set] = {}
    for node in tax.nodes.values():
        seen.setdefault(node.rank, set()).add(node.name)
    assert set(seen) == set(RANKS)
    # a name means one taxon; where a body plan and an order share one, the order is meant
    assert tax.names[" ".join(tokens("spider"))].rank == "order"
