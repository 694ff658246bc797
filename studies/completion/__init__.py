"""The shape-completion studies: the sensor's input statistics against real scans (``input_stats``), the
selector's latent gradients (``latent_gradients``), short runs (``short_completion_run``), catalogue contact
sheets (``catalogue_sheet``)."""
