"""The persistent compilation cache that drumheat.run / run_ensemble switch on."""

import subprocess
import sys
import textwrap


def _run(code, env_extra):
    import os

    env = dict(os.environ, **env_extra)
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1]


def test_run_switches_the_cache_on_in_the_given_folder(tmp_path):
    code = """
        import jax, drumheat as dh
        assert not jax.config.jax_compilation_cache_dir
        dh.run("weigler-static", overrides={"run.duration": 60.0}, progress=False)
        print(jax.config.jax_compilation_cache_dir)
    """
    # (weigler-static's programs each compile in less than MIN_COMPILE_TIME_S: none is written)
    assert _run(code, {"DRUMHEAT_CACHE_DIR": str(tmp_path)}) == str(tmp_path)


def test_a_users_cache_folder_is_kept_and_off_means_off(tmp_path):
    from drumheat.runner.compile_cache import enable_compilation_cache  # noqa: F401 (importable)

    code = f"""
        import jax
        jax.config.update("jax_compilation_cache_dir", {str(tmp_path / 'mine')!r})
        from drumheat.runner.compile_cache import enable_compilation_cache
        print(enable_compilation_cache())
    """
    assert _run(code, {"DRUMHEAT_CACHE_DIR": str(tmp_path / "ours")}) == str(tmp_path / "mine")
    code = """
        import jax
        from drumheat.runner.compile_cache import enable_compilation_cache
        print(enable_compilation_cache(), jax.config.jax_compilation_cache_dir)
    """
    assert _run(code, {"DRUMHEAT_CACHE_DIR": "off"}) == "None None"
