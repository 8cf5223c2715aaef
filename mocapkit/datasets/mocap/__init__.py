"""Motion-capture folders (HDM05, CMU, Bandai): listing and reading clips by their data set's naming, and the HDM05
class tables."""
