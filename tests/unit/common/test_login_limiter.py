"""Failed logins: a few are free, then each costs a lockout that doubles."""

from __future__ import annotations

from fleetlink.common.login_limiter import LoginLimiter


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_lockouts_double_and_a_success_clears_them() -> None:
    clock = Clock()
    limiter = LoginLimiter(free=3, lockout_s=1.0, max_lockout_s=4.0, clock=clock)
    for _ in range(2):
        assert limiter.retry_after("a") == 0
        limiter.failure("a")
    assert limiter.retry_after("a") == 0
    limiter.failure("a")  # the third in a row: locked out 1 s
    assert limiter.retry_after("a") == 1.0
    assert limiter.retry_after("b") == 0  # other clients are not
    clock.now += 1.0
    limiter.failure("a")
    assert limiter.retry_after("a") == 2.0
    clock.now += 2.0
    limiter.failure("a")
    limiter.failure("a")
    assert limiter.retry_after("a") == 4.0  # capped
    limiter.success("a")
    assert limiter.retry_after("a") == 0
    assert (limiter.failed, limiter.refused) == (6, 3)


def test_a_quiet_client_is_forgotten() -> None:
    clock = Clock()
    limiter = LoginLimiter(free=2, forget_s=10.0, clock=clock)
    limiter.failure("a")
    clock.now += 11
    limiter.failure("a")  # a fresh start: one failure, no lockout
    assert limiter.retry_after("a") == 0


def test_the_table_of_clients_is_bounded() -> None:
    limiter = LoginLimiter(max_clients=10, clock=Clock())
    for i in range(100):
        limiter.failure(f"c{i}")
    assert len(limiter._clients) <= 10
