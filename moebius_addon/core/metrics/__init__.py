"""The metrics of the paper (Gram matrices, :mod:`.gram`; open components, :mod:`.open`) and the
saddle-point solves of the projected gradient: dense (:mod:`.saddle`), banded, hs on the tree
and with pinned vertices.
"""
