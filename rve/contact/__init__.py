"""Contact between fibrils: the contact map (element pairs and quadrature-point table)."""
from . import search
from .search import (ContactMap, ElementNeighbours, build_contact_map, candidate_pairs, candidate_pairs_bruteforce,
                     closest_points, element_neighbours, element_segments, gauss_fractions, segment_distance)

__all__ = list(search.__all__)
