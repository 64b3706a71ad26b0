"""``pipeline sync``: raw streams to one synchronised record per press.

The math (clock alignment, resampling, gap filling, presses, with the calibrations of
:mod:`calib`: :mod:`sync.sync` and its steps), the stage runner
(:mod:`sync.sync_stage`), the view (:mod:`sync.sync_view`), the synced file
(:mod:`sync.synced_file`) and its accuracy against the phantom twin (:mod:`sync.sync_accuracy`).
"""
