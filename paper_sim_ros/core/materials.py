"""Named paper materials (the paper's Fig. 12–13): overrides of a scenario's ``sheet`` and
``damage`` sections.

Large ψ (``area_conservation``) folds like card board, small ψ bends like a bank note;
large φ (``fragility``) is rubbery, small φ fragile. ``yield_curvature`` is 2 ε_y / t: about
0.5 % yield strain over the thickness (0.1 mm paper: 100 /m; 0.5 mm card: 20 /m, it keeps
any firm bend), a bank note's tough fibres twice that (200 /m: it springs back).
"""
from __future__ import annotations

MATERIAL_PRESETS: dict[str, dict[str, dict]] = {
    'printer_paper': {
        'sheet': {'grammage': 0.080, 'stretch_stiffness': 3.0e5, 'bend_stiffness': 2.0,
                  'bending_rigidity': 4.0e-4},
        'damage': {'fragility': 2.0, 'area_conservation': 1.0, 'fold_threshold': 0.6,
                   'yield_curvature': 100.0},
    },
    'cardboard': {
        'sheet': {'grammage': 0.300, 'stretch_stiffness': 1.5e6, 'bend_stiffness': 40.0,
                  'bending_rigidity': 1.0e-2},
        'damage': {'fragility': 1.5, 'area_conservation': 1.6, 'fold_threshold': 0.7,
                   'yield_curvature': 20.0},
    },
    'banknote': {
        'sheet': {'grammage': 0.090, 'stretch_stiffness': 4.0e5, 'bend_stiffness': 1.0,
                  'bending_rigidity': 2.0e-4},
        'damage': {'fragility': 4.0, 'area_conservation': 0.4, 'fold_threshold': 0.5,
                   'yield_curvature': 200.0},
    },
}
"""Named materials: per section (``sheet``: ``SheetConfig`` fields, ``damage``:
``DamageConfig`` fields), the values that differ from a plain scenario. SI units."""


def material_preset(name: str) -> dict[str, dict]:
    """A copy of the ``sheet`` and ``damage`` overrides of a named material; ``ValueError``
    naming the known ones for an unknown name."""
    if name not in MATERIAL_PRESETS:
        raise ValueError(f'unknown material {name!r}; known: {", ".join(MATERIAL_PRESETS)}')
    return {section: dict(values) for section, values in MATERIAL_PRESETS[name].items()}
