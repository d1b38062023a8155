"""One run: launcher (set-up, supervision, teardown), lockstep ring, children, the participant contract, specs,
the in-process transport, the per-frame recorder, outputs, thread pools and logs."""
