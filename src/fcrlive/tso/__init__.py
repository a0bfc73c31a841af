"""TSO data files: the Nordic FCR CSV log format, file names, and the mapping to the paper's signals."""
