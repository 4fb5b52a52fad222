"""A schemathesis run against the live admin API of a real edge: cases generated from the served
OpenAPI document (valid and invalid), sent over HTTP with the token; no answer may be a server
error, and every status and body must be one the document declares."""

from __future__ import annotations

import uuid
from pathlib import Path
from typing import Any

import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from schemathesis import Case, GenerationMode
from schemathesis.checks import not_a_server_error
from schemathesis.core.result import Ok
from schemathesis.specs.openapi.checks import response_schema_conformance, status_code_conformance

from tests.integration.test_admin_api import AUTH, edge_config, fleet, next_domain, running_edge


def test_fuzzed_requests_get_no_server_error(zenoh_router: str, tmp_path: Path) -> None:
    domain = next_domain()
    config = edge_config(tmp_path / "spool", zenoh_router, site=f"site-{uuid.uuid4().hex[:8]}", domain=domain)
    with fleet(zenoh_router, domain) as _sim, running_edge(config) as edge:
        schema = schemathesis.openapi.from_url(f"{edge.admin.url}/openapi.json")
        operations = []
        for result in schema.get_all_operations():
            assert isinstance(result, Ok), result
            operations.append(result.ok())
        assert len(operations) >= 12
        cases = st.one_of(
            [
                op.as_strategy(mode)
                for op in operations
                for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE)
            ]
        )
        calls: list[int] = []

        @settings(max_examples=400, deadline=None, database=None, suppress_health_check=list(HealthCheck))
        @given(cases)
        def run(case: Case[Any]) -> None:
            response = case.call(base_url=edge.admin.url, headers=AUTH)
            calls.append(response.status_code)
            case.validate_response(
                response, checks=[not_a_server_error, status_code_conformance, response_schema_conformance]
            )

        run()
        assert len(calls) >= 100
        assert any(code < 300 for code in calls)
        assert any(code == 422 for code in calls)
        # the edge still works after the run
        assert edge.http.get("/mappings", headers=AUTH).status_code == 200
