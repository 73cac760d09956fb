"""The tree engine: the edge hierarchy (:mod:`.bvh`), its near and far fields, the Möbius and
tangent-point energies summed through it, the hs metric without a matrix, and exact contact
queries.
"""
