// placeholder: filled in by the live-runtime work
