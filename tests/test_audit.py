

@pytest.mark.parametrize("kind,key,value", [("soft", "plate.stop", "limit"), ("rigid", "plate.stop_stiffness", 5.0),
                                            ("origami", "plate.rigid_as", "welds")])
def test_a_plate_key_its_kind_has_not_is_refused(capsys, kind, key, value):
    # the origami stop is no part of a soft or rigid plate, nor are welds of a hinged one: they ran unchanged
    assert main(["drag", "--distance", "5", "--plate", kind, "--set", f"{key}={value}"]) == 2
    err = capsys.readouterr().err
    assert f"{key} is used by kind = " in err and len(err.splitlines()) == 1


def test_a_plate_kind_set_drops_the_presets_stop():
    # the preset's origami stop goes with --plate soft; a stop given beside it is still refused
    assert preset("physical").replace(**{"plate.kind": "soft"}).plate.kind == "soft"
    with pytest.raises(SceneError, match="plate.stop is used by kind = 'origami' only"):
        preset("physical").replace(**{"plate.kind": "soft", "plate.stop": "limit"})
