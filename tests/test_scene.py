"""Scene files: loading, overrides, validation messages, round trip."""

import pytest

from drumheat.scene import SceneError, builtin_scenes, iter_keys, load_scene, scene_from_dict


def test_builtin_scenes_load():
    names = builtin_scenes()
    for required in ("weigler-static", "weigler-heating", "weigler-cooling", "weigler-glass-wall"):
        assert required in names
    for name in names:
        scene = load_scene(name)
        assert scene.name == name
        assert scene.n_particles >= 1


def test_overrides_reach_every_level():
    raw_wall = load_scene("weigler-glass-wall").to_dict()
    del raw_wall["heat"]["wall"]["alpha"]
    raw_wall["heat"]["wall"]["model"] = "schluender"
    assert scene_from_dict(raw_wall).heat.wall.alpha is None
    s = load_scene("weigler-glass-wall", ["groups.0.temperature=300", "run.duration=600"])
    assert s.groups[0].temperature == 300.0
    assert s.run.duration == 600.0
    with pytest.raises(SceneError, match="heat.wall.alpha"):
        pass_through = load_scene("weigler-glass-wall", ["heat.wall.model=schluender",
                                                         "heat.wall.alpha=114"])
        del pass_through


def test_override_can_switch_on_an_effect():
    s = load_scene("weigler-static", {"heat.wall.alpha": 1000.0, "drum.wall_temperature": 343.0})
    assert s.heat.effects() == ("contact", "wall", "loss")
    assert s.heat.wall.alpha == 1000.0


def test_toml_round_trip(tmp_path):
    s = load_scene("weigler-static")
    path = tmp_path / "s.toml"
    path.write_text(s.to_toml())
    assert load_scene(path) == s


BAD = [
    ("groups.0.diameter", -0.004, "> 0"),
    ("groups.0.diameter", 0.0, "> 0"),
    ("groups.1.count", 0, ">= 1"),
    ("groups.0.temperature", 0.0, "> 0"),
    ("groups.0.temperature", -5.0, "> 0"),
    ("groups.0.material", "unobtainium", "aluminium"),
    ("heat.contact.model", "magic", "schluender"),
    ("heat.radiosity.alpha", 1.0, "known keys"),
    ("motion.model", "teleport", "static"),
    ("run.duratio", 5.0, "known keys"),
    ("run.duration", "long", "a number"),
    ("groups.0.count", 3.5, "an integer"),
    ("dim", 4, "allowed"),
    ("run.output_interval", 1e6, "run.duration"),
    ("groups.0.diameter", 0.06, "drum.diameter"),
]


@pytest.mark.parametrize("key,value,allowed", BAD)
def test_bad_values_name_the_key(key, value, allowed):
    with pytest.raises(SceneError) as err:
        load_scene("weigler-static", {key: value})
    msg = str(err.value)
    assert f"'{key}'" in msg or f"'{key.rsplit('.', 1)[0]}" in msg
    assert allowed in msg


def test_missing_required_key():
    raw = load_scene("weigler-static").to_dict()
    del raw["groups"][0]["temperature"]
    with pytest.raises(SceneError, match=r"required key 'groups.0.temperature' is missing"):
        scene_from_dict(raw)
    raw = load_scene("weigler-static").to_dict()
    del raw["run"]
    with pytest.raises(SceneError, match=r"required key 'run' is missing"):
        scene_from_dict(raw)


def test_cross_field_rules():
    with pytest.raises(SceneError, match="drum.wall_temperature"):
        load_scene("weigler-static", {"heat.wall.alpha": 100.0})
    with pytest.raises(SceneError, match="heat.contact.alpha"):
        load_scene("weigler-static", {"heat.contact.model": "schluender",
                                      "heat.contact.alpha": 105.0})
    with pytest.raises(SceneError, match="gas.temperature"):
        raw = load_scene("weigler-heating").to_dict()
        del raw["gas"]
        scene_from_dict(raw)
    with pytest.raises(SceneError, match="80 %"):
        load_scene("weigler-static", {"groups.0.count": 300})


def test_unknown_scene_lists_builtins():
    with pytest.raises(SceneError, match="weigler-static"):
        load_scene("no-such-scene")


def test_key_reference_covers_every_table():
    keys = {k for k, *_ in iter_keys()}
    for k in ("run.duration", "drum.diameter", "groups.*.temperature", "heat.contact.alpha",
              "heat.wall.alpha", "heat.loss.alphaA", "gas.temperature", "motion.model"):
        assert k in keys
