"""Factory record: every calibration attempt in a database (SQLite file or PostgreSQL), and reports."""
