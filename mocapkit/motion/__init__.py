"""The motion container, skeleton layouts and skeleton geometry: the bottom layer every other package reads (numpy only, no torch)."""
