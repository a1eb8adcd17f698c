"""The settings of the property-based (hypothesis) tests: 1,000 examples each in CI; more for a longer run
with CROSSVIEW_FUZZ_EXAMPLES=N (e.g. `CROSSVIEW_FUZZ_EXAMPLES=20000 pytest -k fuzz`)."""

import os

from hypothesis import HealthCheck, settings

EXAMPLES = int(os.environ.get("CROSSVIEW_FUZZ_EXAMPLES", "1000"))

FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
