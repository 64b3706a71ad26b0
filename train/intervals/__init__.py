"""How far off a prediction may be: split-conformal intervals, binned, calibrated on presses the
model did not train on.

- :mod:`.levels`: the levels a table holds, and a level asked as its index among them;
- :mod:`.features`: what the bins read of a press (each point's distance from the tip's path,
  the press's depth, the tip start's height above the surface), measured one way for
  calibration and lookup alike;
- :mod:`.quantiles`: the quantile math (the finite-sample rank, the bins' edges, a thin bin's
  fallback to its parent);
- :mod:`.table`: the table itself, in the plain form ``best.pt``'s ``intervals`` and an ONNX
  file's metadata hold;
- :mod:`.lookup`: a table looked up press after press (a haptic loop's), what
  :class:`train.Predictor` answers with a level.

Calibration runs in :mod:`train.training.calibrate` (the fold's validation presses),
coverage on the test presses in :mod:`train.evaluation.coverage`.
"""
