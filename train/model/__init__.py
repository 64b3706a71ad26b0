"""The network: its settings (:mod:`.config`), the cGNN (:mod:`.cgnn`) and its edge
convolution (:mod:`.edgeconv`), the normalisation it learns in (:mod:`.normalise`), and its
answers and errors in SI units (:mod:`.si_units`)."""
