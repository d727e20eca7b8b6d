"""File formats: records from CSV, Parquet, HDF5, the EMPS MAT layout and DataFrames (:mod:`.loaders`), and the
one guard for inputs and outputs with the atomic writer (:mod:`._io`)."""
