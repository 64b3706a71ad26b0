"""fit-solid's JSON read back: the fitted solid, ready to simulate (``simulate --solid``).

The document (``phantom.solid_params``) records the block, the mesh and each element's
stiffness ratio (the interior as the mesh carries it), so that a simulation needs neither the
session nor its interior volume: the same mesh and material are rebuilt from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import BadInput
from data_schema.json_docs import SOLID_PARAMS, validate_json_doc
from data_schema.shape import Shape
from sim.solid.block_mesh import BlockGeometry
from sim.solid.elasticity import Solver
from sim.solid.solid_fit import SolidMaterial
from sim.solid.solid_model import SolidModel


@dataclass
class FittedSolid:
    """A fitted solid: its model, material and each element's stiffness ratio."""

    model: SolidModel
    material: SolidMaterial
    element_ratios: np.ndarray      # (E,) to the block's modulus

    def factorise(self) -> Solver:
        """The fitted stiffness, factorised once for every press."""
        return self.model.factorise(self.element_ratios, self.material.poisson)


def read_solid(path: str | Path) -> FittedSolid:
    """The solid of a ``phantom.solid_params`` document, checked against its own mesh."""
    doc = validate_json_doc(path, SOLID_PARAMS)
    try:
        m, block, mesh = doc["material"], doc["block"], doc["mesh"]
        geometry = BlockGeometry(tuple(block["footprint_m"]), float(block["thickness_m"]),
                                 float(block["top_z_m"]),
                                 Shape.from_json(block["shape"]) if "shape" in block else None)
        material = SolidMaterial(modulus=float(m["modulus_pa"]),
                                 stiffening=float(m["stiffening_per_m2"]),
                                 poisson=float(m["poisson"]), ratios=tuple(m["ratios"]),
                                 contact_radius=float(m["contact_radius_m"]),
                                 reach=float(m["reach_m"]))
        ratios = np.asarray(mesh["element_ratios"], dtype=np.float64)
        model = SolidModel(geometry, float(mesh["spacing_m"]), int(mesh["layers"]))
    except (KeyError, TypeError, ValueError) as e:
        raise BadInput(path, f"unreadable solid ({type(e).__name__}: {e})") from None
    if ratios.shape != (model.elasticity.n_elements,) or not np.all(np.isfinite(ratios)) \
            or np.any(ratios <= 0):
        raise BadInput(path, f"element_ratios holds {ratios.size} values for a mesh of "
                             f"{model.elasticity.n_elements} elements (or one not > 0)")
    return FittedSolid(model, material, ratios)
