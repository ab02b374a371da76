"""Exploration policies: the contract a policy meets, the paper's random walk and the mapping-driven policies."""
