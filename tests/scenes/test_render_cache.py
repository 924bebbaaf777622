"""Determinism, render cache, atomic writes and corruption recovery."""

from __future__ import annotations

import hashlib
import io
import threading
import time

import numpy as np
import pytest

from scenes.radiance_io import read_radiance_exr, write_radiance_exr
from scenes.render import render, render_key
from scenes.render_cache import RenderCache, content_key
from scenes.scenario import RenderSettings, Scenario

pytestmark = pytest.mark.usefixtures("mitsuba_variant")

SMALL = Scenario(
    beacon="v2",
    side="green",
    range_m=8.0,
    yaw_deg=10.0,
    environment="lit-room",
    render=RenderSettings(spp=4, oversampling=1, seed=7),
)


def _digest(radiance) -> str:
    h = hashlib.sha256()
    for c in radiance.components:
        h.update(c.name.encode())
        h.update(c.image_W_m2_sr.tobytes())
    return h.hexdigest()


def test_same_seed_same_bytes_and_second_call_is_cached(tmp_path):
    cache = RenderCache(tmp_path / "cache")
    first = render(SMALL, cache)
    second = render(SMALL, cache)
    uncached = render(SMALL, None)
    assert not first.from_cache and second.from_cache
    assert cache.stats.writes == 1 and cache.stats.hits == 1
    assert _digest(first) == _digest(second) == _digest(uncached)
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    write_radiance_exr(a, first)
    write_radiance_exr(b, second)
    assert a.read_bytes() == b.read_bytes()
    back = read_radiance_exr(a)
    assert _digest(back) == _digest(first) and back.grid == first.grid


def test_other_seed_differs():
    other = Scenario(**{**SMALL.__dict__, "render": RenderSettings(spp=4, oversampling=1, seed=8)})
    assert _digest(render(other)) != _digest(render(SMALL))


def test_led_drive_scales_cached_render_without_rerendering(tmp_path):
    cache = RenderCache(tmp_path / "cache")
    full = render(SMALL, cache)
    half = render(Scenario(**{**SMALL.__dict__, "led_current_mA": 10.0}), cache)
    assert cache.stats.writes == 1 and half.from_cache
    ratio = 0.5**SMALL.led.current_exponent
    np.testing.assert_allclose(
        half.component("led:green").image_W_m2_sr, full.component("led:green").image_W_m2_sr * ratio, rtol=1e-6
    )
    np.testing.assert_array_equal(half.component("ambient").image_W_m2_sr, full.component("ambient").image_W_m2_sr)


@pytest.mark.parametrize("damage", ["truncate", "flip"])
def test_corrupt_entry_is_detected_and_rerendered(tmp_path, damage):
    cache = RenderCache(tmp_path / "cache")
    good = render(SMALL, cache)
    path = cache.path(render_key(SMALL, good.variant, [c.name for c in good.components]))
    blob = bytearray(path.read_bytes())
    if damage == "truncate":
        path.write_bytes(bytes(blob[: len(blob) // 2]))
    else:
        blob[len(blob) // 2] ^= 0xFF
        path.write_bytes(bytes(blob))
    again = render(SMALL, cache)
    assert cache.stats.corrupt == 1 and not again.from_cache
    assert _digest(again) == _digest(good)
    assert render(SMALL, cache).from_cache


def test_no_temporary_files_are_left_behind(tmp_path):
    cache = RenderCache(tmp_path / "cache")
    render(SMALL, cache)
    leftovers = [p for p in (tmp_path / "cache").rglob("*") if p.is_file() and p.suffix == ".tmp"]
    assert leftovers == []


def test_with_led_current_equals_a_render_at_that_current():
    from scenes.render import with_led_current

    direct = render(Scenario(**{**SMALL.__dict__, "led_current_mA": 7.0}))
    rescaled = with_led_current(render(SMALL), 7.0)
    assert _digest(direct) == _digest(rescaled)


def test_an_entry_being_made_is_waited_for_not_made_again(tmp_path):
    # flock locks belong to open file descriptions, so two threads with their own open()
    # exclude each other as two worker processes do
    cache = RenderCache(tmp_path)
    key = content_key("lock-test")
    making, calls, first = threading.Event(), [], {}

    def slow():
        calls.append("slow")
        making.set()
        time.sleep(0.3)
        return {"x": np.arange(3.0)}

    def other():
        calls.append("other")
        return {"x": np.zeros(3)}

    thread = threading.Thread(target=lambda: first.update(result=cache.get_or_make(key, slow)))
    thread.start()
    assert making.wait(10)
    second, from_cache = cache.get_or_make(key, other)
    thread.join()
    assert calls == ["slow"] and from_cache and first["result"][1] is False
    np.testing.assert_array_equal(second["x"], np.arange(3.0))


def test_an_unwritable_cache_still_makes_the_entry(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the cache folder should be")
    arrays, from_cache = RenderCache(blocker).get_or_make(content_key("x"), lambda: {"x": np.ones(2)})
    assert not from_cache and arrays["x"].tolist() == [1.0, 1.0]


def test_an_entry_copied_over_another_is_a_miss_with_a_warning(tmp_path, caplog):
    """Issue 26, hole 4: the digest covers the key, so a swapped entry is never used."""
    cache = RenderCache(tmp_path)
    a, b = content_key("entry a"), content_key("entry b")
    cache.store(a, {"x": np.zeros(3)})
    cache.store(b, {"x": np.ones(3)})
    cache.path(b).write_bytes(cache.path(a).read_bytes())  # a valid entry, under the wrong name
    assert cache.load(b) is None
    assert cache.stats.corrupt == 1 and "another key" in caplog.text and str(cache.path(b)) in caplog.text
    arrays, from_cache = cache.get_or_make(b, lambda: {"x": np.full(3, 2.0)})
    assert not from_cache and arrays["x"].tolist() == [2.0, 2.0, 2.0]
    assert cache.load(b)["x"].tolist() == [2.0, 2.0, 2.0] and cache.load(a)["x"].tolist() == [0.0, 0.0, 0.0]


def test_a_format_1_entry_is_read_once_and_rewritten(tmp_path):
    cache = RenderCache(tmp_path)
    key = content_key("old entry")
    buf = io.BytesIO()
    np.savez_compressed(buf, x=np.arange(4.0))
    legacy = cache.legacy_path(key)
    legacy.parent.mkdir(parents=True)
    legacy.write_bytes(hashlib.sha256(buf.getvalue()).hexdigest().encode() + buf.getvalue())
    assert cache.load(key)["x"].tolist() == [0.0, 1.0, 2.0, 3.0]
    assert cache.stats.migrated == 1 and not legacy.exists() and cache.path(key).is_file()
    assert cache.load(key)["x"].tolist() == [0.0, 1.0, 2.0, 3.0] and cache.stats.migrated == 1


def test_a_format_1_entry_in_the_format_2_folder_is_refused(tmp_path):
    cache = RenderCache(tmp_path)
    key = content_key("planted")
    buf = io.BytesIO()
    np.savez_compressed(buf, x=np.arange(2.0))
    cache.path(key).parent.mkdir(parents=True)
    cache.path(key).write_bytes(hashlib.sha256(buf.getvalue()).hexdigest().encode() + buf.getvalue())
    assert cache.load(key) is None and cache.stats.corrupt == 1
