"""The command line keeps compiled programs on disk by default (JAX's persistent cache), in the
folder --cache-dir or JFLEX_CACHE_DIR names; --no-cache and JFLEX_NO_CACHE=1 turn it off."""

import os
import subprocess
import sys


def _jflex(args, env):
    res = subprocess.run([sys.executable, "-m", "jflex.cli", *args], env=env, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    return res


def test_cli_uses_the_cache_folder_it_is_given(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("JFLEX_CACHE_DIR", "JFLEX_NO_CACHE")}
    folder = tmp_path / "cache"
    _jflex(["--cache-dir", str(folder), "info", "kuka_kr90"], env)
    assert folder.is_dir()
    env_folder = tmp_path / "from_env"
    _jflex(["info", "kuka_kr90"], dict(env, JFLEX_CACHE_DIR=str(env_folder)))
    assert env_folder.is_dir()


def test_cli_no_cache_leaves_nothing(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("JFLEX_CACHE_DIR", "JFLEX_NO_CACHE")}
    folder = tmp_path / "cache"
    _jflex(["--no-cache", "--cache-dir", str(folder), "info", "kuka_kr90"], env)
    assert not folder.exists()
    _jflex(["info", "kuka_kr90"], dict(env, JFLEX_CACHE_DIR=str(folder), JFLEX_NO_CACHE="1"))
    assert not folder.exists()
