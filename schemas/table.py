"""A warehouse table defined once: its columns (name, DuckDB type, Arrow type, unit, description) and keys.

From a `Table` come the comments (`COMMENT ON …`), the Arrow schema of its Parquet files, the column list of an
INSERT, the DDL of a new table or of new columns, and the check of rows built for it: a row with a key the table
does not have, or without one it has, raises `RowShapeError` (nothing is dropped or filled in silently).

The definitions live in `schemas/tables/` (one module per area); `schemas.tables.TABLES` holds them all, and a
test compares them with a freshly migrated warehouse (information_schema) and with the Parquet files of a run.
Migrations already applied are history and stay as written; a new table or column is made from its definition
(`create_sql`, `add_columns_sql`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

# The Arrow type of each DuckDB type, as Parquet files and Arrow readers get it: times are UTC instants
# (`timestamp[us, tz=UTC]`), as the warehouse's naive TIMESTAMPs are UTC by convention.
ARROW_OF_DUCKDB = {
    "VARCHAR": "string", "BIGINT": "int64", "INTEGER": "int32", "DOUBLE": "float64", "BOOLEAN": "bool",
    "TIMESTAMP": "timestamp[us, tz=UTC]", "DATE": "date32", "DOUBLE[]": "list<float64>",
}


class RowShapeError(ValueError):
    """Rows built for a table have a key the table does not define, or lack one it does."""


@dataclass(frozen=True)
class Column:
    name: str
    duckdb: str  # DuckDB type as information_schema.columns.data_type spells it, e.g. DOUBLE, TIMESTAMP, DOUBLE[]
    unit: str | None  # e.g. "t", "kn", "NM", "h", "degree", "UTC" (times); None: no unit (names, counts, flags)
    description: str  # the column's comment in the warehouse
    not_null: bool = False
    allowed: tuple[str, ...] = ()  # the only values (a CHECK constraint), e.g. statuses
    arrow: str | None = None  # Arrow type when it differs from ARROW_OF_DUCKDB[duckdb]

    @property
    def arrow_type(self) -> str:
        return self.arrow or ARROW_OF_DUCKDB[self.duckdb]

    def ddl(self) -> str:
        out = f"{self.name} {self.duckdb}"
        if self.not_null:
            out += " NOT NULL"
        if self.allowed:
            out += f" CHECK ({self.name} IN ({', '.join(_quoted(v) for v in self.allowed)}))"
        return out


@dataclass(frozen=True)
class Table:
    name: str
    description: str
    columns: tuple[Column, ...]
    primary_key: tuple[str, ...] = ()
    by_name: dict[str, Column] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "by_name", {c.name: c for c in self.columns})
        if len(self.by_name) != len(self.columns):
            raise ValueError(f"table {self.name}: a column is defined twice")
        unknown = [k for k in self.primary_key if k not in self.by_name]
        if unknown:
            raise ValueError(f"table {self.name}: primary key column(s) {unknown} not defined")

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.columns]

    def names_except(self, *left_out: str) -> list[str]:
        """The column names without `left_out` (each must be a column: a typo raises)."""
        self._known(left_out)
        return [n for n in self.names if n not in left_out]

    def describe(self, name: str) -> str:
        return self.by_name[name].description

    def comments(self) -> dict[str, str]:
        return {c.name: c.description for c in self.columns}

    # --- DDL (for tables and columns that are new; applied migrations stay as written) ------------------------
    def create_sql(self) -> str:
        parts = [c.ddl() for c in self.columns]
        if self.primary_key:
            parts.append(f"PRIMARY KEY ({', '.join(self.primary_key)})")
        return f"CREATE TABLE IF NOT EXISTS {self.name} ({', '.join(parts)});"

    def add_columns_sql(self, *names: str) -> str:
        """ALTER TABLE … ADD COLUMN for `names` (new columns: nullable, as DuckDB adds them)."""
        self._known(names)
        return "\n".join(f"ALTER TABLE {self.name} ADD COLUMN IF NOT EXISTS {self.by_name[n].name} "
                         f"{self.by_name[n].duckdb};" for n in names)

    # --- Arrow ---------------------------------------------------------------------------------------------------
    def arrow_schema(self, without: Sequence[str] = ()):
        """The Arrow schema of the table's Parquet files (`without`: columns not in the file, e.g. a partition)."""
        import pyarrow as pa  # here: only writers of Parquet need it

        return pa.schema([(c.name, _arrow(c.arrow_type)) for c in self.columns if c.name not in set(without)])

    # --- rows ----------------------------------------------------------------------------------------------------
    def check_keys(self, keys: Iterable[str], *, columns: Sequence[str] | None = None, what: str = "row") -> None:
        """Raise RowShapeError unless `keys` are exactly `columns` (default: every column of the table)."""
        expected = list(self.names if columns is None else columns)
        self._known(expected)
        keys = list(keys)
        unknown = [k for k in keys if k not in self.by_name]
        not_here = [k for k in keys if k in self.by_name and k not in expected]
        missing = [k for k in expected if k not in set(keys)]
        if unknown or not_here or missing:
            said = [f"{', '.join(unknown)} not defined for {self.name} (schemas/tables)" if unknown else "",
                    f"{', '.join(not_here)} not expected here" if not_here else "",
                    f"missing {', '.join(missing)}" if missing else ""]
            raise RowShapeError(f"{what} for table {self.name}: " + "; ".join(s for s in said if s))

    def empty_row(self, **values) -> dict:
        """A row with every column None except `values` (a key that is not a column raises)."""
        self._known(values)
        return {**dict.fromkeys(self.names), **values}

    def check_rows(self, rows: Iterable[Mapping], *, columns: Sequence[str] | None = None) -> None:
        """`check_keys` of every row (rows with the same keys in the same order are checked once)."""
        seen: set[tuple] = set()
        for i, row in enumerate(rows):
            keys = tuple(row)
            if keys not in seen:
                self.check_keys(keys, columns=columns, what=f"row {i}")
                seen.add(keys)

    def take(self, df, *, columns: Sequence[str] | None = None):
        """The frame `df` (an import's validated rows) as `columns` (default: all) in the table's order: every one
        must be there (missing raises); other columns of the input file are not the table's and are left out."""
        expected = list(self.names if columns is None else columns)
        self._known(expected)
        missing = [c for c in expected if c not in df.columns]
        if missing:
            raise RowShapeError(f"rows for table {self.name}: missing {', '.join(missing)}")
        return df[expected]

    def _known(self, names: Iterable[str]) -> None:
        unknown = [n for n in names if n not in self.by_name]
        if unknown:
            raise RowShapeError(f"table {self.name} has no column(s) {', '.join(unknown)}")


def _quoted(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def _arrow(name: str):
    import pyarrow as pa

    simple = {"string": pa.string(), "int64": pa.int64(), "int32": pa.int32(), "float64": pa.float64(), "bool": pa.bool_(),
              "timestamp[us, tz=UTC]": pa.timestamp("us", tz="UTC"), "date32": pa.date32(),
              "list<float64>": pa.list_(pa.float64())}
    return simple[name]


def comment_sql(tables: Iterable[Table]) -> str:
    """COMMENT ON statements for the tables and their columns."""
    lines = []
    for t in tables:
        lines.append(f"COMMENT ON TABLE {t.name} IS {_quoted(t.description)};")
        lines += [f"COMMENT ON COLUMN {t.name}.{c.name} IS {_quoted(c.description)};" for c in t.columns]
    return "\n".join(lines)
