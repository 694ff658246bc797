"""The body-fit studies: held-out Anny people and FAUST (``evaluate``), the start regressor's training
(``train_regressor``), the body-fit rows of the canonical table (``body_fit_rows``), FAUST through the
completion net (``faust_chain``)."""
