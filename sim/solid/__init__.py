"""The solid model of the phantom: volumetric finite elements of the block with its interior
(scikit-fem), pressed like the lab's presses, fitted to them (``pipeline fit-solid``) and
simulated for pre-training (``pipeline simulate --solid``)."""
