"""The figures of the studies: one PNG per function, drawn with matplotlib's Agg backend."""
