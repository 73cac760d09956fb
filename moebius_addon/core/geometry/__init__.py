"""Curves and what they meet: polygons and their checks, the vertex layout of knots and links,
OBJ files, collision and contact, pins, constraints, obstacles, containers and tubes.
"""
