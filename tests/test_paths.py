"""Paths refused before anything runs, in one line that names what is wrong with them."""

import os

import pytest

from finrft.cli import main


def test_an_output_name_too_long_for_its_temporary_is_refused_before_the_run(tmp_path, capsys):
    # 240 characters is a legal name; the temporary it is written under first is not.
    out = tmp_path / ("a" * 240 + ".h5")
    assert main(["drag", "--distance", "5", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "file name is too long" in err and "give a shorter name" in err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("make, said", [(os.mkdir, "it is a directory, not a file"),
                                        (os.mkfifo, "it is a pipe, not a file"),
                                        (lambda path: None, "no such file")])
def test_a_model_path_that_is_no_file_says_what_it_is(tmp_path, capsys, make, said):
    model = tmp_path / "robot.xml"
    make(model)
    assert main(["run", str(model), "--example", "sand_swimmer", "--quiet"]) == 2
    assert capsys.readouterr().err == f"finrft: error: cannot read model file {model}: {said}\n"
