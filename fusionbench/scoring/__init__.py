"""Scoring against the truth: the theoretical limits and the attainable bound of an alignment (:mod:`.bound`,
:mod:`.bound_model`) and the metrics of a misalignment history (:mod:`.metrics`). Imports only the simulation layer."""
