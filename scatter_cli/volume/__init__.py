"""Points in space around a surface and their labels: the box and near points (``source``),
exact closest points, generalized winding numbers, ray parity."""
