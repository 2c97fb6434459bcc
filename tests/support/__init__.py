"""Helpers the tests share: imported as ``tests.support.<module>`` from any test folder."""
