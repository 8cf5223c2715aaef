"""Lightning modules and the train / eval / export / predict entry points."""
