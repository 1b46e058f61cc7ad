"""Benchmarks of splineplan beside its peers (SUMO's router, sumolib); see RESULTS.md."""
