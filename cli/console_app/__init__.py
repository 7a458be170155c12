"""The operator's web console (`jitroute console`): a read-only Starlette application over a data root, its pages
drawn in the browser from the package's own script, style and land picture (no CDN, works air-gapped)."""
