"""The paper's cGNN training settings, each stated once (as :mod:`sim.msm.paper` states its
MSM): the dataclasses' defaults (:class:`train.training.train_params.TrainOptions`,
:class:`train.model.config.CGNNConfig`) and so the ``paper`` recipe (:mod:`train.training.recipes`)
and ``pipeline train``'s option defaults.

The paper (section "Training Setup", "Hyperparameters"): 250 epochs, batches of 32, Adam
with an initial learning rate of 1e-4, the loss alpha L_d + MSE of the force change with
alpha = 88, and k = 5 neighbours in the k-NN graph.

Plain numbers: the command line reads its defaults here without loading torch. The paper's
loss and its constant learning rate are the first members of
:class:`~train.training.train_params.Loss` and :class:`~train.training.train_params.Schedule`.
"""

K = 5                # neighbours per point, itself included
LR = 1e-4            # Adam's step size
BATCH = 32           # examples per batch
EPOCHS = 250
ALPHA = 88.0         # the loss's weight of the mean distance L_d (m) against the force MSE (N^2)
