"""Test harnesses shipped with the package: the reader fuzzer that the tests and benchmarks share."""
