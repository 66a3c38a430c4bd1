"""Video-to-template retrieval (CASA section 3.2): rendered bank views, query crops, scoring, search."""
