"""The flight log of a ground-station run: its records, the crash-safe writer and the reader."""
