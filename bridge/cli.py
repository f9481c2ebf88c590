"""``follow-robot``: the same policies on an emulated or a real robot, and a live web monitor.

::

    follow-robot emulate --listen socket://127.0.0.1:5760 [--framing reference|robust]
        [--firmware reference|fixed] [--scenario S] [--seed 0] [--config thesis]
    follow-robot run --port URL --policy NAME [--framing reference|robust]
        [--perception sim|sim:HOST:PORT|replay:LOG.csv|realsense:MODEL.pt] [--duration S]
        [--log OUT.csv] [--command auto|duty|speed] [--seed N] [--monitor] [--http HOST:PORT]
    follow-robot monitor --sim [--policy NAME] [--scenario S] [--seed N] [--config C]
        [--http HOST:PORT]                       (the robot's options are refused: no robot)
    follow-robot monitor --port URL [--perception ...] [--http HOST:PORT]   (a robot, from stop)

(also ``python -m bridge ...``). ``URL`` is anything pyserial opens: ``/dev/ttyUSB0``,
``socket://127.0.0.1:5760`` (the emulator), ``loop://``. The monitor serves
``http://127.0.0.1:8000/`` by default; any other host needs ``--token`` (or the environment
variable ``PERSONFOLLOW_MONITOR_TOKEN``, which ``ps`` does not show), which the page's URL then
carries (``/?token=...``). Bad arguments give one line on stderr and exit status 2. A robot
session raises its limit of open files to the hard one (:func:`_raise_file_limit`).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import signal
import sys
import time
import urllib.parse
from collections.abc import Sequence
from typing import Any, NoReturn

from bridge.address import host_text
from bridge.link import LinkError, SerialLink
from bridge.perception import PerceptionError
from bridge.protocol import FRAMINGS
from bridge.sources import open_source

__all__ = ["main"]

PROG = "follow-robot"
USAGE_ERROR = 2
FIRMWARES = ("reference", "fixed")  # bridge.mcu.FIRMWARES, without importing the simulator
LOOPBACK_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})  # bridge.monitor.app's
COMMANDS = ("auto", "duty", "speed")  # bridge.runner.COMMAND_MODES, without numpy
# The robot's options (None when not given): their values on a robot, and those monitor --sim
# has no use for (refused there); --seed, --config, --http and --token serve both.
ROBOT_DEFAULTS = {"framing": "reference", "perception": "sim", "command": "auto"}
SIM_UNUSED = ("port", "framing", "perception", "command", "duration", "log")
TOKEN_ENV = "PERSONFOLLOW_MONITOR_TOKEN"  # --token when none is given: ps shows arguments, not it


class UsageError(Exception):
    """Bad arguments: one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < value <= 86400:
        raise argparse.ArgumentTypeError(f"{text} is out of range: must be in (0, 86400] s")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"{text} is out of range: must be in [0, 2**63)")
    return value


def _http(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    bracketed = host.startswith("[") and host.endswith("]")
    host = (host[1:-1] if bracketed else host) or "127.0.0.1"
    if ":" in host and not bracketed:  # "::1" would read as host "::" and port 1
        raise argparse.ArgumentTypeError(
            f"{text!r} is not HOST:PORT (an IPv6 host in brackets: [::1]:8000)"
        )
    if not (port.isascii() and port.isdigit()) or not 0 <= int(port) <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT (port 0-65535)")
    return host, int(port)


def _config(text: str) -> Any:
    from follow_env.tasks.person_follow.config import config_from_text

    try:
        return config_from_text(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _parser() -> _Parser:
    parser = _Parser(prog=PROG, description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="subcommand", required=True, parser_class=_Parser)

    emulate = sub.add_parser("emulate", help="emulate the robot's MCU and its world")
    emulate.add_argument("--listen", default="socket://127.0.0.1:5760", help="socket://HOST:PORT")
    emulate.add_argument("--framing", choices=FRAMINGS, default="reference")
    emulate.add_argument("--firmware", choices=FIRMWARES, default="reference")
    emulate.add_argument("--scenario", default=None, help="the world's scenario (--config's)")
    emulate.add_argument("--seed", type=_seed, default=0, help="the world's episode seed")
    emulate.add_argument("--config", type=_config, default="thesis", help="env preset or JSON")

    def robot_options(p: _Parser) -> None:
        # The robot's options default to None, so that `monitor --sim`, which has no robot, can
        # refuse one given rather than ignore it (the robot's defaults are ROBOT_DEFAULTS).
        p.add_argument("--port", help="the serial URL (a port, socket://HOST:PORT, loop://)")
        p.add_argument("--framing", choices=FRAMINGS, help="reference (default) | robust")
        p.add_argument("--perception", help="sim (default) | replay:LOG.csv | realsense:M")
        p.add_argument("--command", choices=COMMANDS, help="auto (default) | duty | speed")
        p.add_argument("--duration", type=_positive, default=None, help="stop after S seconds")
        p.add_argument("--log", default=None, help="write the step log here (CSV)")
        p.add_argument("--seed", type=_seed, default=None, help="reset the sim world to it")
        p.add_argument("--config", type=_config, default="thesis", help="robot preset or JSON")
        p.add_argument("--http", type=_http, default=("127.0.0.1", 8000), help="monitor address")
        p.add_argument(
            "--token",
            default=None,
            help=f"required by the monitor off loopback; default: ${TOKEN_ENV} (which, unlike "
            "an argument, ps does not show others)",
        )

    run = sub.add_parser("run", help="drive a robot with a policy")
    robot_options(run)
    run.add_argument("--policy", required=True, help="pn, gsmpn:tuned, ppo, a model path ...")
    run.add_argument("--monitor", action="store_true", help="serve the live monitor too")

    monitor = sub.add_parser("monitor", help="the live web monitor")
    robot_options(monitor)
    monitor.add_argument("--sim", action="store_true", help="watch the simulator, no hardware")
    monitor.add_argument("--policy", default=None, help="--sim: the starting mode (stop)")
    monitor.add_argument("--scenario", default=None, help="--sim: the scenario (--config's)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    # A path typed with bytes that are not UTF-8 (a replay file, a --log without a --log check
    # of its name) is printed in the summary after the session: under a UTF-8 locale Python's
    # streams refuse its surrogates, and the summary would end in a traceback. Printed as the
    # bytes were typed instead.
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None and getattr(stream, "errors", None) == "strict":
            reconfigure(errors="surrogateescape")
    try:
        args = _parser().parse_args(argv)
        return _dispatch(args)
    except UsageError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return USAGE_ERROR
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM outside a session (which stops the wheels)
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130


def _dispatch(args: argparse.Namespace) -> int:
    # Ctrl-C must reach us even when a shell started us with SIGINT ignored (a background job).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _interrupt)  # `kill` stops as cleanly as Ctrl-C
    if args.subcommand != "emulate":
        host, _ = args.http
        given = "--token"
        if args.token is None and os.environ.get(TOKEN_ENV):
            args.token, given = os.environ[TOKEN_ENV], TOKEN_ENV
        if host not in LOOPBACK_HOSTS and not args.token:
            raise UsageError(
                f"--http {host_text(host)}: not loopback; give --token (or set {TOKEN_ENV}) so "
                "that only you can drive the robot"
            )
        if args.token is not None:
            try:  # bytes that are not UTF-8 arrive as lone surrogates: no page could send them
                args.token.encode("utf-8")
            except UnicodeEncodeError:
                raise UsageError(
                    f"{given} {args.token!r} is out of range: must be text (its bytes are not "
                    "UTF-8)"
                ) from None
    if args.subcommand == "emulate":
        return _emulate(args)
    if args.subcommand == "monitor" and args.sim:
        return _monitor_sim(args)
    if not args.port:
        raise UsageError(f"{args.subcommand} needs --port URL (or, for monitor, --sim)")
    if args.subcommand == "monitor":
        # a robot's monitor starts it stopped, on purpose: the page chooses what drives it
        for option, value in (("--scenario", args.scenario), ("--policy", args.policy)):
            if value not in (None, "stop"):
                raise UsageError(
                    f"{option} {value}: monitor --port starts the robot stopped and the page "
                    "chooses the mode (--scenario and --policy are for monitor --sim; or use "
                    "run --policy NAME --monitor)"
                )
    if args.subcommand == "run" and args.policy == "manual" and not args.monitor:
        # the commands come from the monitor's page: without it the robot would idle unasked
        raise UsageError(
            "--policy manual: the monitor's page sends the manual commands; add --monitor (or "
            "give --policy stop to hold the wheels at zero while the session logs)"
        )
    for name, value in ROBOT_DEFAULTS.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    return _run(args, monitor=args.subcommand == "monitor" or args.monitor)


def _env_config(args: argparse.Namespace, scenario: str | None = None, check: bool = False) -> Any:
    """The environment's configuration from ``--config`` (and ``--scenario``); ``check``: also
    refuse what its scenario cannot use, as building the world would, but before it is built."""
    from follow_env.tasks.person_follow.task import TASK

    try:
        config = TASK.resolve_config(args.config, scenario=scenario)
        if check:
            TASK.check(config)  # the scenario's name, what it can use, how many people
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return config


def _check_listen(url: str) -> None:
    """Refuse an ``emulate --listen`` the emulator could not listen on, naming the option."""
    from bridge.perception import parse_socket_url

    try:
        _, port = parse_socket_url(url)
    except ValueError as exc:
        raise UsageError(f"--listen {exc}") from None  # the message starts with the URL
    if port == 65535:  # the camera listens on PORT + 1
        raise UsageError(f"--listen {url!r}: port 65535 leaves no PORT + 1 for the camera")


def _raise_file_limit() -> None:
    """Raise this process's soft limit of open files to its hard one: a robot session holds
    the serial port, the camera, its log and the monitor's connections, and the common soft
    limit (1024) is often far below the hard one. Where it cannot, it stays as it was."""
    try:
        import resource
    except ImportError:  # not a POSIX system: no such limit to raise
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = hard if hard != resource.RLIM_INFINITY else max(soft, 1 << 16)
    if soft != resource.RLIM_INFINITY and soft < target:
        with contextlib.suppress(ValueError, OSError):  # (macOS caps it below its hard limit)
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))


def _emulate(args: argparse.Namespace) -> int:
    _check_listen(args.listen)  # before the simulator is imported and its world built
    from bridge.emulator import Emulator

    config = _env_config(args, args.scenario, check=True)
    try:
        emulator = Emulator(args.listen, args.framing, args.firmware, config, args.seed)
    except (ValueError, OSError) as exc:
        raise UsageError(str(exc)) from None
    host, port = emulator.camera_address
    print(
        f"{PROG}: emulating the {args.firmware} firmware ({args.framing} framing) on "
        f"{emulator.url}; the world's camera ({config.scenario.name}, seed {args.seed}) on "
        f"{host_text(host)}:{port}. Ctrl-C ends.",
        flush=True,
    )
    with contextlib.suppress(KeyboardInterrupt):
        emulator.serve_forever()
    print(f"{PROG}: emulator stopped: {emulator.stats}, {emulator.mcu.stats}", flush=True)
    return 0


def _policy_factory(built: dict[str, Any] | None = None) -> Any:
    from policies import make_policy

    def build(name: str) -> Any:
        # an agent built to see whether the robot can run it is handed out once, then new ones
        policy = (built or {}).pop(name, None)
        return make_policy(name) if policy is None else policy

    return build


def _shipped_agents() -> tuple[dict[str, Any], list[str]]:
    """The shipped PersonFollow agents a monitor may offer beyond its fixed modes (``ppo_ahead``,
    ``ppo_law``, ``ppo_mecanum``), built (whether a robot can run one is read from the agent
    itself), and why any of them could not be loaded."""
    from bridge.monitor.hub import MODES
    from policies import make_policy
    from policies.learned.ppo import SHIPPED

    names = [n for n, task in SHIPPED.values() if task == "person_follow" and n not in MODES]
    agents, broken = {}, []
    for name in names:
        try:
            agents[name] = make_policy(name)
        except ValueError as exc:  # a missing or damaged agent folder: not offered, said why
            broken.append(f"{name} ({exc})")
    return agents, broken


def _ahead_of(agents: dict[str, Any]) -> dict[str, Any] | None:
    """The one reading ahead the agents read (None if none reads one, or they differ)."""
    reads = [getattr(a, "reads_ahead", None) for a in agents.values()]
    wanted = {repr(r): r for r in reads if r}
    return next(iter(wanted.values())) if len(wanted) == 1 else None


def _offer(agents: dict[str, Any], check: Any) -> tuple[dict[str, Any], list[str]]:
    """The agents ``check`` accepts (it raises ``ValueError`` for one the robot cannot run),
    and why each other one is not offered."""
    offered, skipped = {}, []
    for name, agent in agents.items():
        try:
            check(agent)
        except ValueError as exc:
            skipped.append(str(exc))
        else:
            offered[name] = agent
    return offered, skipped


def _modes(start: str, offered: dict[str, Any], skipped: list[str]) -> tuple[str, ...]:
    """The monitor's modes (said on stdout): the fixed ones, the offered agents, and the
    starting policy's name when it is none of them."""
    from bridge.monitor.hub import monitor_modes

    modes = monitor_modes([*offered, start] if start not in ("stop", "manual") else offered)
    note = f" (not offered: {'; '.join(skipped)})" if skipped else ""
    print(f"{PROG}: monitor modes {', '.join(modes)}{note}", flush=True)
    return modes


def _start_monitor(args: argparse.Namespace, hub: Any) -> Any:
    from bridge.monitor.app import serve

    host, port = args.http
    try:
        server = serve(hub, host, port, args.token)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    except RuntimeError as exc:  # the port is in use, the address is not this machine's
        raise UsageError(f"--http {host_text(host)}:{port}: {exc}") from None
    # quoted: a token with +, &, # or % would otherwise not survive the page's URL
    query = f"?token={urllib.parse.quote(args.token, safe='')}" if args.token else ""
    print(f"{PROG}: monitor on {server.url}{query}", flush=True)
    return server


def _monitor_sim(args: argparse.Namespace) -> int:
    given = [f"--{n} {getattr(args, n)}" for n in SIM_UNUSED if getattr(args, n) is not None]
    if given:  # refused rather than ignored: the user meant something by it
        it, is_ = ("it", "it is") if len(given) == 1 else ("them", "they are")
        raise UsageError(
            f"{', '.join(given)}: monitor --sim has no robot and does not use {it} "
            f"({is_} for run and monitor --port)"
        )
    start = args.policy or "stop"
    _raise_file_limit()
    # checked before the simulator is imported, the agents load and the server starts
    config = _env_config(args, args.scenario, check=True)
    from bridge.monitor.hub import MonitorHub
    from bridge.monitor.sim import SimDriver
    from follow_env.tasks.person_follow.spec import ahead_settings

    agents, broken = _shipped_agents()
    ahead = _ahead_of(agents)
    if ahead and ahead_settings(config.perception) is None:
        # the simulated camera publishes what the agents read ahead (the laws and ``ppo`` read
        # the first two entries; the reading has draws of its own, so the world is the same)
        config = dataclasses.replace(
            config, perception=dataclasses.replace(config.perception, **ahead)
        )
    hub = MonitorHub(start)
    try:
        # the scenario is the configuration's (--scenario is in it), not the driver's default
        driver = SimDriver(
            hub, _policy_factory(), config.scenario.name, seed=args.seed or 0, config=config
        )
        driver.check(start)  # a bad name fails here, not in the driver's thread
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    offered, skipped = _offer(agents, driver.runnable)
    hub.modes = _modes(start, offered, [*skipped, *broken])
    server = _start_monitor(args, driver.hub)
    driver.start()
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        driver.stop()
        server.stop()
    return 0


def _run(args: argparse.Namespace, monitor: bool) -> int:
    from bridge.fit import check_command, check_platform
    from bridge.runlog import check_log_path
    from bridge.runner import PolicyError, Runner, RunnerConfig

    _raise_file_limit()  # before the serial port, the camera and the monitor open any
    if args.framing == "reference" and args.command == "speed":
        # the reference firmware reads the wire's two values as percent duty (reference §1)
        raise UsageError(
            "--command speed: the reference framing carries duty commands only (the reference "
            "firmware's percent duty); use --command duty or auto, or --framing robust"
        )
    if args.log is not None:
        try:  # now, not at the end of a session whose data it would lose
            check_log_path(args.log)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        # The log's policy and scenario columns hold these as typed, and the log is UTF-8 text:
        # refused now, not at the end of the session, when the log could not be written.
        if args.subcommand == "run":
            _check_text("--policy", args.policy, "policy")
        _check_text("--perception", args.perception, "scenario")
    config = _env_config(args)
    try:  # the robot drives with two wheels: refused now, not by a crash in the session
        check_platform(config.platform)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    # with the monitor, the shipped agents that command [v, w] are modes too; the perception
    # is checked when one is chosen (Runner._runnable), as it is known once started
    agents, broken = _shipped_agents() if monitor else ({}, [])
    agents, skipped = _offer(agents, check_command)
    skipped += broken
    factory = _policy_factory(dict(agents))
    policy_name = args.policy if args.subcommand == "run" else "stop"
    try:
        policy = factory(policy_name) if policy_name not in ("stop", "manual") else None
        if policy is not None:
            try:
                check_command(policy)
            except ValueError as exc:
                raise ValueError(f"--policy {policy_name}: {exc}") from None
        run_config = RunnerConfig(duration_s=args.duration, command=args.command)
        # a camera that can publish the reading ahead does so for the policy, or else for the
        # agents the monitor offers
        ahead = getattr(policy, "reads_ahead", None) or _ahead_of(agents)
        perception = open_source(args.perception, args.port, args.seed, ahead)
    except (ValueError, PerceptionError) as exc:
        raise UsageError(str(exc)) from None
    try:
        link = SerialLink(args.port, args.framing)
    except LinkError as exc:
        raise UsageError(str(exc)) from None
    hub = server = None
    if monitor:
        from bridge.monitor.hub import MonitorHub

        hub = MonitorHub(policy_name, modes=_modes(policy_name, agents, skipped))
        server = _start_monitor(args, hub)
    meta = {"policy": policy_name, "scenario": f"robot:{args.perception}", "seed": args.seed}
    try:
        try:
            runner = Runner(
                link,
                policy if policy is not None else _Idle(policy_name),
                perception,
                config.platform,
                run_config,
                log=args.log,
                meta=meta,
                monitor=hub,
                policy_factory=factory,
            )
        except ValueError as exc:  # what the runner refuses before it starts (checked above)
            raise UsageError(str(exc)) from None
        result = runner.run()
    except (LinkError, PerceptionError, PolicyError) as exc:
        # mid-session, the result is on the error: the summary, and where the log went
        return _report(getattr(exc, "result", None), str(exc))
    finally:
        link.close()
        if server is not None:
            server.stop()
    return _report(result)


def _check_text(option: str, value: str, column: str) -> None:
    """Refuse ``value`` if it is not text the step log can hold: its ``column`` is UTF-8, and
    bytes of a command line that are not UTF-8 arrive as lone surrogates, which it cannot be.

    :raises UsageError: one line naming ``option`` and ``value`` (its bytes as typed).
    """
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise UsageError(
            f"{option} {_shown(value)}: is not UTF-8 text, which the step log's {column} column "
            "holds; rename the file or folder, or run without --log"
        ) from None


def _shown(value: str) -> str:
    """``value`` printable: a byte that is not UTF-8 as ``\\xff``, as typed (the surrogate a
    command line decodes it to, ``\\udcff``, is not what the user sees)."""
    try:
        return value.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # a surrogate no byte decodes to: given from Python, not typed
        return value.encode("utf-8", "backslashreplace").decode("utf-8")


def _report(result: Any, error: str = "") -> int:
    """Say how a session went: the summary (where the log is) on stdout, then on stderr one
    line with whatever went wrong (``error``, the wheel loop's failure, no stop command, a log
    not where asked); the exit status, 1 if anything did."""
    problems = [error] if error else []
    if result is not None:
        print(f"{PROG}: {result.summary()}", flush=True)
        for problem in (result.failure, result.stop_error, result.log_error):
            if problem and problem not in problems:
                problems.append(problem)
    if problems:
        print(f"{PROG}: error: {'; '.join(problems)}", file=sys.stderr)
        return 1
    return 0


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


class _Idle:
    """The policy of the ``stop`` and ``manual`` start modes (the monitor picks the rest)."""

    def __init__(self, name: str) -> None:
        self.name = name

    def reset(self) -> None:
        pass

    def act(self, obs: Any) -> Any:
        return (0.0, 0.0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
