"""GcPauses: counts the collector's runs per generation and keeps the longest pause."""

import gc

from freejoint_common.node_tools import GcPauses


def test_each_collection_is_counted_in_its_generation_with_its_pause():
    pauses = GcPauses()
    gc.callbacks.append(pauses)
    try:
        gc.collect(1)
        gc.collect(2)
    finally:
        gc.callbacks.remove(pauses)
    assert pauses.count[1] >= 1 and pauses.count[2] >= 1
    assert pauses.longest[2] > 0.0
    text = pauses.report()
    assert text.startswith('garbage collections: gen0 ')
    assert ', gen2 %d (longest ' % pauses.count[2] in text and text.endswith(' ms)')


def test_start_freezes_what_exists_and_hooks_the_collector_once():
    pauses = GcPauses()
    try:
        pauses.start()
        pauses.start()
        assert gc.callbacks.count(pauses) == 1
        assert gc.get_freeze_count() > 0
    finally:
        while pauses in gc.callbacks:
            gc.callbacks.remove(pauses)
        gc.unfreeze()
