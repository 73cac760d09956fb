"""Knots as knots: the catalogue of curves, the shipped knot table, braid words and PD codes,
invariants, identification, diagrams drawn as space curves, and tangled starts.
"""
