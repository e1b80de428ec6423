"""The operator's 3-D view and controls in viser. Reads state snapshots and calls back into the small
interface the server hands it; never imports `server`."""
