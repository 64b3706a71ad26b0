"""``pipeline extract``: synced presses to static states in the phantom frame.

The math (:mod:`extract.static_states` per press, :mod:`extract.phantom_frame`,
:mod:`extract.extract` over sessions), the synced files read (:mod:`extract.synced_presses`),
the settings (:mod:`extract.extract_params`), the stage runner (:mod:`extract.extract_stage`)
and the view (:mod:`extract.extract_view`).
"""
