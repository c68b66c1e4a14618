"""The notebooks as tests (nbmake): the tuning notebook fits on the moss garden for about a
minute and a half, so it runs with the slow tests (`make test-all`)."""
import pytest

SLOW = {"tuning.ipynb"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in SLOW:
            item.add_marker(pytest.mark.slow)
