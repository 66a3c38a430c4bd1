"""`bank search --explain`: how each embedder scored the top results and what decided the order."""

from __future__ import annotations

from .search import SearchResult


def _ordinal(n: int) -> str:
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def explain_table(res: SearchResult) -> tuple[list[tuple[str, str]], list[list[str]], str]:
    """(columns, rows, title): per match and embedder "distance #rank term": the aggregated cosine
    distance, the asset's rank by that embedder alone and its term of the fused score."""
    cols = [("rank", "right"), ("asset", "left"), ("score", "right")]
    cols += [(f"{e}: dist #rank term", "right") for e in res.embedders]
    sem = res.semantic_weight is not None
    if sem:
        cols += [("label", "left"), ("shares", "left"), ("semantic: score term", "right")]
    rows = []
    for i, m in enumerate(res.matches, 1):
        row = [str(i), m.name, f"{m.score:+.2f}"]
        for e in res.embedders:
            row.append(f"{m.distances[e]:.3f} #{m.ranks.get(e, '-')} {m.terms.get(e, float('nan')):+.2f}")
        if sem:
            shares = f"{m.taxon[0]} {m.taxon[1]}" if m.taxon else "-"
            row += [m.label or "-", shares, f"{m.semantic or 0:.2f} {m.terms.get('semantic', 0.0):+.2f}"]
        rows.append(row)
    term = {"zsum": "z-score of the distance", "sum": "the distance", "rank": "rank - 1"}[res.fusion]
    title = (
        f"per embedder: {res.aggregation} cosine distance, #rank among the {res.candidates} candidates by "
        f"that embedder alone, and its term of the {res.fusion} score ({term}; the terms add up to the "
        f"score; lower is better)"
    )
    if sem:
        title += (
            f"; semantic: the asset's label, the taxon it shares with the video's most likely animal, "
            f"how much of what the classifier sees it is the bank's nearest relative of (relative to the best "
            f"asset's, times how surely the classifier sees an animal: 0..1) and its term (-{res.semantic_weight:g} x it)"
        )
    return cols, rows, title


def explain_lines(res: SearchResult) -> list[str]:
    """Sentences: which embedders put the first match first, and what separated it from the second."""
    if not res.matches:
        return []
    first = res.matches[0]
    lines = []
    if res.semantic_weight is not None:
        seen = ", ".join(f"{c} {p:.2f}" for c, p in res.classes) or "no animal class"
        lines.append(f"the video looks like (ImageNet classes, mean over its crops): {seen}.")
        if first.taxon:
            lines.append(f"#1 {first.name} ({first.label}) shares the {first.taxon[0]} {first.taxon[1]}.")
        else:
            lines.append(f"#1 {first.name} ({first.label or 'no label'}) shares no taxon with it.")
    ranks = ", ".join(f"{e} {_ordinal(first.ranks[e])}" for e in res.embedders if e in first.ranks)
    lines.append(f"#1 {first.name}: ranked {ranks} by the embedders alone.")
    terms = [e for e in [*res.embedders, "semantic"] if e in first.terms]
    if len(res.matches) > 1 and len(terms) > 1:
        second = res.matches[1]
        diffs = {e: second.terms[e] - first.terms[e] for e in terms}
        parts = ", ".join(
            f"{e} {d:+.2f} ({'for' if d >= 0 else 'against'} {first.name})"
            for e, d in sorted(diffs.items(), key=lambda kv: -kv[1])
        )
        lines.append(f"#1 {first.name} over #2 {second.name} by {second.score - first.score:.2f}: {parts}.")
    return lines
