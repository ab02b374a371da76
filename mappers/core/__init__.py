"""What every method family shares: the sensors' vocabulary, fused histories, anchors and the
affine fit, neighbour graphs, the flicker of a visibility history, errors and the map scores.

Import the modules themselves (``mappers.core.sensors``, ...): this package hands on no names, so
that the world can import the sensor vocabulary without loading scikit-learn.
"""
