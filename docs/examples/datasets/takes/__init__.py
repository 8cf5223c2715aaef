"""A folder of motion files named ``<action>_<performer>_<take>.<ext>`` (docs/extending.md#add-a-data-set)."""
