"""Benchmarks: chorjax against a PyTorch peer (``python -m benchmarks.run``). Not part of the tests."""
