"""Shared fixtures of the package's tests."""

import os

import pytest

import cosserat


@pytest.fixture
def on_gpu():
    """Calls `build()`, which builds something on the GPU, and returns what it built; without a GPU
    adapter the test is skipped, or fails when ``COSSERAT_REQUIRE_GPU=1`` (as in CI, where
    lavapipe must be there)."""

    def build(make):
        try:
            return make()
        except cosserat.SceneError as e:
            if "no GPU adapter" not in str(e):
                raise
            if os.environ.get("COSSERAT_REQUIRE_GPU") == "1":
                pytest.fail(f"COSSERAT_REQUIRE_GPU=1 but there is no adapter: {e}")
            pytest.skip(f"no GPU adapter: {e}")

    return build
