"""Poisson-disk thinning of a candidate stream: close pairs, the greedy, the search for an
exact count, spacing statistics."""
