"""The log's redaction of students' hidden numbers: what is hidden, for how long, at what cost.

Each test makes its own :class:`SecretRegistry` (the process-wide one is only ever added to by
``keep_out_of_logs``), except the one that checks the module's functions, which releases what it
registers.
"""

from __future__ import annotations

import logging
import re
import sys
import threading

import pytest

from eha_app.runtime import redaction
from eha_app.runtime.redaction import (
    HIDDEN,
    MAX_MESSAGE_CHARS,
    RedactingFilter,
    SecretRegistry,
    number_forms,
    register_student,
    registry_stats,
)

# the kinds of number a hidden parameter may be: ordinary, negative, tiny, huge, integer-valued
VALUES = (4500.291346, -1234.56789, 3.0e-11, 1.7e+9 + 0.123, 2.0e+16 / 3, 4500.0, 0.031416926)


def _formatted(registry: SecretRegistry, msg: str, args=(), exc: Exception | None = None) -> str:
    """``msg % args`` logged through a filter of ``registry``, with ``exc``'s traceback if given."""
    record = logging.LogRecord("eha_app", logging.WARNING, __file__, 1, msg, args, None)
    if exc is not None:
        try:
            raise exc
        except type(exc):
            record.exc_info = sys.exc_info()
    assert RedactingFilter(registry).filter(record)
    return logging.Formatter().format(record)


def test_every_form_of_every_kind_of_number_fits_the_one_fixed_token():
    # the lookup finds a form only where the fixed expression finds a number: every form must be one whole
    rng_values = [v * 10.0 ** k for v in VALUES for k in range(-3, 4)]
    for value in rng_values:
        for form in number_forms(value):
            assert redaction._NUMBER.fullmatch(form), (value, form)


@pytest.mark.parametrize("value", VALUES)
def test_every_form_of_a_registered_number_is_hidden_in_a_message_and_a_traceback(value):
    registry = SecretRegistry()
    with registry.register_student("lab-3", "ada", [value]):
        for form in number_forms(value):
            # where a log writes a number: after "=", in brackets, at a sentence's end, after a unit's space
            for template in ("M = {} kg", "(M={})", "M is {}.", "got [{}, 1.5]", "{}"):
                text = _formatted(registry, "value %s", (template.format(form),),
                                  exc=ValueError(f"bad: {template.format(form)}"))
                assert form not in text.replace(HIDDEN, " "), (form, text)
                assert text.count(HIDDEN) == 2, text        # the message's and the traceback's


def test_numbers_that_share_digits_with_a_registered_one_are_not_hidden():
    registry = SecretRegistry()
    with registry.register_student("lab-3", "ada", [4500.291346]):
        for other in ("4500.2914", "14500.291346", "4500.2913467", "45002.91346", "450.0291346", "4500.291345",
                      "x4500.3", "4500.3kg", "4500.3_1", "v4.5003e+03", "4500.29134", "4.50029e+031", "0.291346"):
            assert registry.redact(f"M = {other} kg") == f"M = {other} kg", other
        # a form is hidden whole, not a shorter form inside it ("[hidden]13"), and a sign stays as written
        assert registry.redact("4500.2913, -4500.29 and +4500.3.") == "[hidden], -[hidden] and +[hidden]."


def test_a_students_numbers_go_with_their_last_page_and_another_students_stay():
    registry = SecretRegistry()
    ada = 4123.456789
    bob = 2718.281828
    page1 = registry.register_student("lab-3", "ada", [ada])
    page2 = registry.register_student("lab-3", "ada", [ada])
    bobs = registry.register_student("lab-3", "bob", [bob])
    text = f"ada: {ada:.6g}, bob: {bob:.7e}"
    assert registry.redact(text) == f"ada: {HIDDEN}, bob: {HIDDEN}"
    page1.release()
    page1.release()                         # a page's cleanup running twice does not release its neighbour
    assert registry.redact(text) == f"ada: {HIDDEN}, bob: {HIDDEN}"
    page2.release()
    assert registry.redact(text) == f"ada: {ada:.6g}, bob: {HIDDEN}"
    assert registry.stats() == redaction.RegistryStats(students=1, pages=1, forms=len(number_forms(bob)), strings=0)
    bobs.release()
    assert registry.stats() == redaction.RegistryStats(students=0, pages=0, forms=0, strings=0)
    assert registry.redact(text) == text


def test_students_sharing_a_form_keep_it_hidden_until_both_leave():
    registry = SecretRegistry()
    a = registry.register_student("lab-3", "ada", [4500.29])
    b = registry.register_student("lab-3", "bob", [4500.291])       # both print as 4500.29 at 6 digits
    a.release()
    assert registry.redact("M = 4500.29") == f"M = {HIDDEN}"
    b.release()
    assert registry.redact("M = 4500.29") == "M = 4500.29"


def test_registering_a_student_again_counts_the_page_and_nothing_else():
    registry = SecretRegistry()
    values = [4500.291346, 1500.123456, 0.031416926]
    first = registry.register_student("lab-3", "ada", values)
    once = registry.stats()
    again = [registry.register_student("lab-3", "ada", values) for _ in range(5)]
    assert registry.stats() == redaction.RegistryStats(students=1, pages=6, forms=once.forms, strings=0)
    assert once.forms == len(set().union(*(number_forms(v) for v in values)))
    # the same student in another exercise, or with other values, is counted apart (released apart)
    other = registry.register_student("lab-4", "ada", values)
    assert registry.stats().students == 2 and registry.stats().forms == once.forms
    for page in (first, *again, other):
        page.release()
    assert registry.stats().forms == 0


def test_a_registration_rebuilds_no_expression_however_many_students_there_are(monkeypatch):
    registry = SecretRegistry()
    registry.keep("f00dfeedf00dfeedf00d")
    strings_pattern, number_pattern = registry._strings_pattern, redaction._NUMBER
    compiled = []
    real_compile = re.compile
    monkeypatch.setattr(redaction.re, "compile", lambda *a, **k: compiled.append(a) or real_compile(*a, **k))
    pages = [registry.register_student("lab-3", f"s{k}", [4000.0 + k / 7, 1500.0 + k / 3]) for k in range(300)]
    registry.keep("f00dfeedf00dfeedf00d")          # the exercise's key again, as every page's start gives it
    assert registry.redact(f"M = {4000.0 + 299 / 7:.8g}") == f"M = {HIDDEN}"
    for page in pages:
        page.release()
    assert compiled == []
    assert registry._strings_pattern is strings_pattern and redaction._NUMBER is number_pattern


def test_a_long_lived_string_is_hidden_as_a_whole_word():
    registry = SecretRegistry()
    registry.keep("f00dfeedf00dfeedf00d", "abc")       # 3 characters: too short to be anyone's secret
    line = "GET /teacher/ws?token=f00dfeedf00dfeedf00d&x=abc"
    assert registry.redact(line) == f"GET /teacher/ws?token={HIDDEN}&x=abc"
    assert registry.redact("f00dfeedf00dfeedf00d0") == "f00dfeedf00dfeedf00d0"      # part of a longer word
    assert registry.stats().strings == 1


def test_many_threads_registering_and_releasing_leave_a_consistent_registry():
    registry = SecretRegistry()
    students = [f"s{k}" for k in range(20)]
    held: list = []
    held_lock = threading.Lock()
    start = threading.Barrier(8)

    def work(seed: int) -> None:
        start.wait()
        mine = []
        for k in range(300):
            student = students[(seed * 7 + k) % len(students)]
            mine.append(registry.register_student("lab-3", student, [4000.0 + int(student[1:]) / 7]))
            if k % 3 == 2:
                mine.pop(0).release()
        with held_lock:
            held.extend(mine)

    threads = [threading.Thread(target=work, args=(seed,)) for seed in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    stats = registry.stats()
    assert stats.pages == len(held) == 8 * 200
    assert stats.students == len({page.student for page in held})
    assert stats.forms == len(set().union(*(number_forms(4000.0 + int(s[1:]) / 7) for s in {p.student for p in held})))
    for page in held:
        page.release()
    assert registry.stats() == redaction.RegistryStats(students=0, pages=0, forms=0, strings=0)


def test_the_modules_functions_use_the_process_wide_registry():
    before = registry_stats()
    with register_student("test_redaction", "ada", [7123.456789]) as page:
        assert _formatted(SecretRegistry(), "M = %s", ("7123.4568",)) == "M = 7123.4568"
        record = logging.LogRecord("eha_app", logging.WARNING, __file__, 1, "M = %s", ("7123.4568",), None)
        assert RedactingFilter().filter(record) and record.getMessage() == f"M = {HIDDEN}"
        assert "7123" not in repr(page) and "test_redaction" not in repr(page)
    assert page.released and registry_stats() == before


def test_a_cut_message_does_not_end_in_a_secrets_first_digits():
    registry = SecretRegistry()
    with registry.register_student("lab-3", "ada", [4500.291346]):
        # the cut falls inside the number: 4500.29, its first digits unrounded, is no registered form
        message = "x" * (MAX_MESSAGE_CHARS - 7) + " 4500.291346 kg" + "y" * 100
        text = _formatted(registry, "%s", (message,))
        assert "4500" not in text and text.endswith("characters more)")
