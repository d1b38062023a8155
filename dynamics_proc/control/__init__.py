"""The offloading controller: its plug-in contract, the built-in controller, section estimates, fill
strategies, the fused fill estimator, feed-forward through turns and how it copes with field conditions."""
