"""The shape-quality studies: CPCD2 against the field's metrics (``cpcd2_study``), thesis table 4.5 (``canvas_study``)."""
