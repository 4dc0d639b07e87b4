"""Recordings from data as published: text (CSV, TSV, whitespace, one value per line, joints in
separate files), MATLAB .mat and ROS 2 bags, read into one raw table (tables.py), mapped onto
the recording schema and, for time series, put on the control grid with every repair counted
(assemble.py, grid.py). ``serpar import`` is the command-line edge (cli/cmd_import.py)."""
