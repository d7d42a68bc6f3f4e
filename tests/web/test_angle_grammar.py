"""The operator page's angle parser (``angles`` in service/web/static/page.js, which turns the
campaign form's angles into poses at once) reads the server's grammar
(:func:`calibration.angles.parse_angles`, the authority): the same angles for every text the
server takes, and nothing the server would take for a text it refuses."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calibration.angles import parse_angles
from sim_core.errors import InvalidInputError

pytestmark = pytest.mark.timeout(300)

#: texts of both forms and near misses
TEXTS = ["-30, -10, 10, 30", "-30,-10 10  30", " 0 ", "-10:10:5", "0:10:4", "0:1:0.1",
         "-55:55:2.2", "-70:70:5", "1e1, .5, 5., +3", "0,,30", "0:10", "0:10:0", "10:-10:5",
         "0:1e300:1e-300", "0,x", "nan", "Infinity", "0x10", "1_000", "", "-", "0:10:-1",
         "0 : 10 : 5", "1:2:3:4", "-360:360:1"]


def page_angles(page, text: str):
    return page.js("return angles(arguments[0])", text)


def server_angles(text: str):
    try:
        return list(parse_angles(text, field="angles"))
    except InvalidInputError:
        return None


def assert_page_reads_as_the_server(page, text: str) -> None:
    from_page, from_server = page_angles(page, text), server_angles(text)
    if from_server is not None:
        assert from_page == from_server, text
    else:  # what the page sends is refused too: a text, not a number, or no angle at all
        sent_numbers = [a for a in from_page if isinstance(a, int | float) and math.isfinite(a)]
        assert not from_page or len(sent_numbers) < len(from_page) or \
            server_angles(", ".join(repr(float(a)) for a in sent_numbers)) is None, text


def test_the_pages_parser_reads_the_servers_grammar(server, page):
    page.load("campaigns")
    for text in TEXTS:
        assert_page_reads_as_the_server(page, text)


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=st.text(alphabet="0123456789.,:-+e ", max_size=20)
       | st.builds(lambda a, b, s: f"{a}:{b}:{s}", st.integers(-360, 360).map(lambda k: k / 4),
                   st.integers(-360, 360).map(lambda k: k / 4),
                   st.integers(1, 200).map(lambda k: k / 8)))
def test_random_texts_read_the_same_on_the_page_and_the_server(server, page, text):
    if page.js("return typeof angles") != "function":
        page.load("campaigns")
    assert_page_reads_as_the_server(page, text)
