"""The on-disk store: asset bank, video store, fits and motion priors under one root."""
