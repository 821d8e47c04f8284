"""Live extraction (frame change, setting change) in an interactive session: the cursor
progress shows it, and a frame over the object's Live Particle Limit is not extracted (it
cannot be cancelled; a bake can) on a setting change or while the timeline plays or is
scrubbed; it is once the timeline stops, and a frame set any other way (a frame step, an
exporter stepping frames) or Refresh is always extracted. Background bpy has no UI, so the
tests stand in for an interactive session where the add-on asks whether it is one and
whether the timeline moves."""

import threading

import bpy
import pytest
from conftest import assert_mesh_equals, FRAME_26, import_sequence, reference

PARTICLES = 4732  # in each dam break frame of the demo sequence
LIMIT = 1000


def over_limit(frame, limit=LIMIT, frame_change=False):
    when = "extracted when the timeline stops; " if frame_change else ""
    return (
        f"Frame {frame}: {PARTICLES:,} particles, over the live limit of {limit:,}: {when}"
        "bake the range (Esc cancels), Refresh, or raise Live Particle Limit"
    )


@pytest.fixture
def interactive(addon, monkeypatch):
    """The add-on sees a Blender with a UI (background bpy is not one)."""
    monkeypatch.setattr(addon.importer, "_interactive", lambda: True)


@pytest.fixture
def timeline(addon, monkeypatch):
    """Whether the add-on sees the timeline playing or scrubbed (`timeline.moving`); the
    timer that extracts held-back frames is unregistered afterwards (background bpy never
    runs timers: the tests call it)."""

    class Timeline:
        moving = True

    state = Timeline()
    monkeypatch.setattr(addon.importer, "timeline_moving", lambda: state.moving)
    yield state
    if bpy.app.timers.is_registered(addon.importer.extract_held_back_frames):
        bpy.app.timers.unregister(addon.importer.extract_held_back_frames)


@pytest.fixture
def extractions(addon, monkeypatch):
    """Records the progress argument of every extraction (which still runs)."""
    calls = []
    real = addon.extraction.extract

    def extract(particles, params, progress=None):
        calls.append(progress)
        return real(particles, params, progress=progress)

    monkeypatch.setattr(addon.extraction, "extract", extract)
    return calls


class WindowManager:
    """Records the cursor progress calls of a window manager."""

    def __init__(self):
        self.calls = []

    def progress_begin(self, lo, hi):
        self.calls.append(("begin", lo, hi))

    def progress_update(self, value):
        self.calls.append(("update", value))

    def progress_end(self):
        self.calls.append(("end",))


def test_the_default_limit_is_half_a_million(scene, demo_sequence):
    assert import_sequence(demo_sequence[0]).isobar.live_particle_limit == 500_000


def test_a_frame_over_the_limit_keeps_the_mesh_and_says_why(
    scene, isobar, demo_sequence, interactive, timeline, extractions
):
    assert len(isobar.Particles.read(str(FRAME_26))) == PARTICLES
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    first = reference(isobar, demo_sequence[0])
    assert_mesh_equals(obj, first)
    extractions.clear()

    settings.live_particle_limit = LIMIT  # frame 1 is shown already: not read again
    assert not settings.status_error, settings.status
    scene.frame_set(2)  # while the timeline plays
    assert settings.status_error and settings.status == over_limit(2, frame_change=True)
    assert not settings.status_warnings
    assert extractions == []  # counted, not extracted
    assert_mesh_equals(obj, first)  # the mesh shown is kept
    settings.iso = 0.55  # a setting change is live too
    assert settings.status == over_limit(2)
    assert extractions == [] and len(obj.data.vertices) == first.n_points

    settings.live_particle_limit = 0  # no limit: the frame held back is extracted now
    assert not settings.status_error, settings.status
    assert len(extractions) == 1
    assert_mesh_equals(obj, reference(isobar, demo_sequence[1], iso=0.55))
    settings.live_particle_limit = PARTICLES  # exactly the frame's count is allowed
    scene.frame_set(3)
    assert not settings.status_error, settings.status
    assert_mesh_equals(obj, reference(isobar, demo_sequence[2], iso=0.55))


def test_baking_is_not_limited_and_plays_back_over_the_limit(scene, isobar, demo_sequence, tmp_path, interactive):
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    settings.cache_directory = str(tmp_path / "cache")
    settings.live_particle_limit = LIMIT
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    folder = tmp_path / "cache" / settings.cache_name
    assert sorted(p.name for p in folder.iterdir()) == [f"frame_00000{i}.npz" for i in (1, 2, 3)]
    for frame in (2, 3, 1):
        scene.frame_set(frame)  # the bake is read, whatever the particle count
        assert not settings.status_error and "bake" in settings.status, settings.status
        assert_mesh_equals(obj, reference(isobar, demo_sequence[frame - 1], attributes=["velocity"]))


def test_renders_and_background_mode_are_not_limited(scene, addon, isobar, demo_sequence, monkeypatch):
    importer = addon.importer
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    settings.live_particle_limit = LIMIT
    assert bpy.app.background and importer.live_limit(settings) == 0  # scripts get every frame
    scene.frame_set(2)
    assert not settings.status_error, settings.status
    assert_mesh_equals(obj, reference(isobar, demo_sequence[1]))

    monkeypatch.setattr(importer, "_interactive", lambda: True)
    assert importer.live_limit(settings) == LIMIT
    importer.set_rendering(True)  # a render needs its frame
    try:
        assert importer.live_limit(settings) == 0
        scene.frame_set(3)
        assert not settings.status_error, settings.status
        assert_mesh_equals(obj, reference(isobar, demo_sequence[2]))
    finally:
        importer.set_rendering(False)


def test_live_extraction_shows_cursor_progress_and_always_ends_it(scene, addon, demo_sequence, extractions, monkeypatch):
    wm = WindowManager()
    monkeypatch.setattr(addon.importer, "_progress_window_manager", lambda: wm)
    obj = import_sequence(demo_sequence[0])
    assert len(extractions) == 1 and callable(extractions[0])
    assert wm.calls[0] == ("begin", 0.0, 1.0) and wm.calls[-1] == ("end",)
    updates = [c[1] for c in wm.calls if c[0] == "update"]
    assert updates and all(0.0 <= v <= 1.0 for v in updates)
    assert [c[0] for c in wm.calls].count("begin") == 1 and [c[0] for c in wm.calls].count("end") == 1

    wm.calls.clear()
    assert bpy.ops.isobar.refresh() == {"FINISHED"} and len(extractions) == 2  # Refresh is live too
    assert wm.calls[0][0] == "begin" and wm.calls[-1] == ("end",)
    wm.calls.clear()
    scene.frame_set(1)  # the frame shown: nothing extracted, no progress
    assert len(extractions) == 2 and wm.calls == []

    def broken(particles, params, progress=None):
        progress(0.5, "seeds")
        raise ValueError("the core failed half way")

    monkeypatch.setattr(addon.extraction, "extract", broken)
    scene.frame_set(2)
    assert obj.isobar.status_error and "the core failed half way" in obj.isobar.status
    assert wm.calls == [("begin", 0.0, 1.0), ("update", 0.5), ("end",)]  # ended on error too


def test_cursor_progress_only_with_a_ui_on_the_main_thread(addon, monkeypatch):
    importer = addon.importer
    assert bpy.app.background and importer._progress_window_manager() is None
    monkeypatch.setattr(importer, "_interactive", lambda: True)
    assert importer._progress_window_manager() == bpy.context.window_manager
    off_main = []
    thread = threading.Thread(target=lambda: off_main.append(importer._progress_window_manager()))
    thread.start()
    thread.join()
    assert off_main == [None]  # a render's frame handlers run on its thread
    importer.set_rendering(True)
    try:
        assert importer._progress_window_manager() is None
    finally:
        importer.set_rendering(False)


def test_a_frame_held_back_while_the_timeline_moves_is_extracted_when_it_stops(
    scene, addon, isobar, demo_sequence, interactive, timeline, extractions
):
    importer = addon.importer
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    settings.live_particle_limit = LIMIT
    first = reference(isobar, demo_sequence[0])
    extractions.clear()
    scene.frame_set(2)
    scene.frame_set(3)  # playback goes on: still held back
    assert settings.status == over_limit(3, frame_change=True) and extractions == []
    assert_mesh_equals(obj, first)
    assert bpy.app.timers.is_registered(importer.extract_held_back_frames)
    assert importer.extract_held_back_frames() == importer._SETTLE_INTERVAL  # still moving: look again later
    assert extractions == []

    timeline.moving = False  # playback stopped on frame 3: its surface is extracted
    assert importer.extract_held_back_frames() is None
    assert not settings.status_error, settings.status
    assert len(extractions) == 1
    assert_mesh_equals(obj, reference(isobar, demo_sequence[2]))


def test_frame_steps_and_exporters_stepping_frames_are_not_limited(
    scene, addon, isobar, demo_sequence, interactive, timeline, extractions
):
    """An exporter (Blender's Alembic or USD export) sets each frame and writes what the
    mesh shows: a frame held back would be exported as the previous frame's surface."""
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    settings.live_particle_limit = LIMIT
    timeline.moving = False
    assert addon.importer.live_limit(settings, addon.importer.FRAME) == 0
    assert addon.importer.live_limit(settings, addon.importer.SETTING) == LIMIT
    for frame in (2, 3, 1):
        scene.frame_set(frame)
        assert not settings.status_error, settings.status
        assert_mesh_equals(obj, reference(isobar, demo_sequence[frame - 1]))
    assert not bpy.app.timers.is_registered(addon.importer.extract_held_back_frames)


def test_refresh_extracts_a_frame_over_the_limit(scene, isobar, demo_sequence, interactive, timeline, extractions):
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    settings.live_particle_limit = LIMIT
    extractions.clear()
    settings.iso = 0.55  # held back
    assert settings.status == over_limit(1) and extractions == []
    assert bpy.ops.isobar.refresh() == {"FINISHED"}  # the user asks for this frame
    assert not settings.status_error, settings.status
    assert len(extractions) == 1
    assert_mesh_equals(obj, reference(isobar, demo_sequence[0], iso=0.55))


def test_the_timeline_is_read_only_on_the_main_thread(addon, monkeypatch):
    importer = addon.importer
    assert importer.timeline_moving() is False  # background bpy: no window plays

    class Screen:
        is_animation_playing, is_scrubbing = True, False

    class Window:
        screen = Screen()

    monkeypatch.setattr(importer, "_windows", lambda: [Window()])
    assert importer.timeline_moving() is True
    Screen.is_animation_playing, Screen.is_scrubbing = False, True
    assert importer.timeline_moving() is True
    off_main = []
    thread = threading.Thread(target=lambda: off_main.append(importer.timeline_moving()))
    thread.start()
    thread.join()
    assert off_main == [False]


def test_frames_a_bake_sets_hold_back_the_other_surfaces(scene, addon, demo_sequence, interactive, timeline):
    """Baking a surface from a particle system sets each frame: the other surfaces in the
    scene are held back over their limit as during playback (an export is not running),
    and extracted once the bake ends."""
    importer = addon.importer
    timeline.moving = False
    obj = import_sequence(demo_sequence[0])
    obj.isobar.live_particle_limit = LIMIT
    other = import_sequence(demo_sequence[0])
    assert importer.live_limit(obj.isobar, importer.FRAME) == 0
    with importer.baking(other):
        assert importer.live_limit(obj.isobar, importer.FRAME) == LIMIT
        scene.frame_set(2)
        assert obj.isobar.status == over_limit(2, frame_change=True)
        assert importer.extract_held_back_frames() == importer._SETTLE_INTERVAL  # not while baking
    assert importer.extract_held_back_frames() is None
    assert not obj.isobar.status_error, obj.isobar.status
