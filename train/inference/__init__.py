"""Using a trained cGNN: the SI model's entries, the :class:`Predictor` on its backends (with
the head split for a known mesh and region mode), and the ONNX export and its runner."""
