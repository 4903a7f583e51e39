"""Haptify's normative JSON data (schemas, metric definitions, code catalogue) as package data.

Read it through :func:`haptify.schemas.load`, never by path from a checkout.
"""
