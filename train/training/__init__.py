"""Training a cGNN: the run's settings (:mod:`.train_params`, :mod:`.recipes`), the loop,
checkpoints and their migration from older forms, the run's variant, and the train runner."""
