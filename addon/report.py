"""Report text of a flatten run: the status-bar line and the WARNING lines (bpy-free)."""


def summary_line(r: dict) -> str:
    """One line for the status bar: islands, holes, ratio, bound, flips, conformality, range, time."""
    parts = [f"Conformal flatten {r['object']!r} ({r['boundary'].lower()}): {r['triangles']} triangles"]
    n_isl = r.get('islands')
    if n_isl and n_isl > 1:
        parts.append(f"{n_isl} islands")
    if r.get('islands_failed'):
        parts.append(f"{r['islands_failed']} island(s) skipped")
    if r.get('holes_filled'):
        parts.append(f"filled {r['holes_filled']} hole{'s' if r['holes_filled'] != 1 else ''}")
    if r.get('holes_cut'):
        parts.append(f"cut {r['holes_cut']} hole{'s' if r['holes_cut'] != 1 else ''} open")
    if r.get('selection') == 'selected faces':
        parts.append(f"{r.get('flattened_polygons')} selected faces")
    parts.append(f"mu ratio {r['mu_ratio']:.4g}")
    if r.get('bound_vertex') is not None:
        parts.append(f"certified bound {r['bound_vertex']:.4g}")
    parts.append(f"{r['flips']} flips")
    parts.append(f"qc mean {r['qc_mean']:.4f}")
    if r.get('conformal_factor_range'):
        lo, hi = r['conformal_factor_range']
        parts.append(f"mu in [{lo:.4g}, {hi:.4g}]")
    parts.append(f"{r['seconds']['total']:.2f} s")
    return ', '.join(parts)


def run_summary(reports: list) -> str:
    """The operator's INFO line for one or several meshes."""
    if len(reports) == 1:
        return summary_line(reports[0])
    isl = sum(r['islands'] for r in reports)
    holes = sum(r['holes_filled'] for r in reports)
    flips = sum(r['flips'] for r in reports)
    worst_qc = max(r['qc_mean'] for r in reports)
    worst_mu = min(r['mu_ratio'] for r in reports)
    total = max(r['seconds']['total'] for r in reports)
    text = (f"Conformal flatten: {len(reports)} meshes ({', '.join(r['object'] for r in reports)}), "
            f"{isl} islands")
    if holes:
        text += f", filled {holes} hole{'s' if holes != 1 else ''}"
    return text + (f", worst mu ratio {worst_mu:.4g}, {flips} flips, worst qc mean {worst_qc:.4f}, "
                   f"{total:.2f} s")


def warnings_of(reports: list) -> list:
    """WARNING lines: objects and islands skipped, quality warnings of the core (flips, overlaps,
    poor conformality, no convergence), packing fallbacks."""
    out = []
    for r in reports:
        for s in r.get('skipped_objects', []):
            out.append(f"skipped {s['error']}")
        for isl in r.get('island_reports', []):
            if 'error' in isl:
                out.append(f"{r['object']!r}: skipped {isl['error']}")
        for w in r.get('warnings', []):
            out.append(f"{r['object']!r}: {w}")
        if r.get('pack_note'):
            out.append(f"{r['object']!r}: {r['pack_note']}")
    return out
