"""The network: its settings (:mod:`.config`), the cGNN (:mod:`.cgnn`), its edge convolution
(:mod:`.edgeconv`) and that layer's neighbour search (:mod:`.knn`), the normalisation it
learns in (:mod:`.normalise`), and its answers and errors in SI units (:mod:`.si_units`)."""
