"""``pipeline split``: k-fold manifests (``phantom.folds`` 2.0) over a states file.

The math (:mod:`split.split`: groups to folds, numpy only), the settings and the data's
defaults (:mod:`split.split_params`), the stage runner
(:mod:`split.split_stage`: the manifest read from and written beside the states file) and the
view (:mod:`split.split_view`).
"""
