"""``volsr bench``: quality against time, side by side (scenes -> run -> report; docs/performance.md)."""
