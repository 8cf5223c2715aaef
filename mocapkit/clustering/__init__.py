"""NMF motion clustering: the NMF family (NMF, orthogonal NMF, GNMF, NMC), their sample graphs and the bag-of-clip-words classifier."""
