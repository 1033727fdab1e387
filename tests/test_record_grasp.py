"""The Meshcat page of a recorded grasp: a headless Chromium draws the scene from it."""

from pathlib import Path

import pytest
from pydrake.geometry import StartMeshcat

from drake_grasp.apps.record_grasp import (
    MIN_SCENE_FRACTION,
    drawn_scene_fraction,
    find_chromium,
    screenshot_html,
)
from drake_grasp.robot.paths import REPO_ROOT

SHIPPED_PAGE = REPO_ROOT / "reports" / "grasp_cnn_rp.html"

needs_chromium = pytest.mark.skipif(find_chromium() is None, reason="no Chromium (CI installs it)")


def test_the_recorded_grasp_page_is_shipped_with_its_replay():
    page = SHIPPED_PAGE.read_text()
    assert "meshcat_inline_assets" in page and page.count("animation") > 10  # the scene and its replay


@needs_chromium
def test_the_shipped_page_draws_the_scene_and_an_empty_page_does_not(tmp_path: Path):
    assert drawn_scene_fraction(screenshot_html(SHIPPED_PAGE, tmp_path / "shipped.png")) > MIN_SCENE_FRACTION
    empty_page = tmp_path / "empty.html"
    empty_page.write_text(StartMeshcat().StaticHtml())
    assert drawn_scene_fraction(screenshot_html(empty_page, tmp_path / "empty.png")) < MIN_SCENE_FRACTION
