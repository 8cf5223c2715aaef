"""Gait recognition from silhouettes: GEI + PCA + LDA, the multi-task CNN's Lightning module, metrics, export and the CASIA-B benchmark."""
