"""Runs: the one door to the numerics (:mod:`.engine`), the optimizers (:mod:`.methods`), what
they share (:mod:`.base`), adaptive resolution, growth, the entry points (:mod:`.flow`) and batch
runs. Empty on purpose: the rooms below import from here, so nothing is imported eagerly.
"""
