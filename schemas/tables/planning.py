"""Warehouse tables: fleet operation planning (ports, availability, contracts, distances, plans)."""

from schemas.table import Column, Table
from schemas.tables.fleet import RAW, REASON, REJECTED_AT, SOURCE_FILE

PORTS = Table('ports', 'ports the planner may use, with the position of their pilot station (at sea)', (
    Column('port', 'VARCHAR', None, 'port name'),
    Column('lat', 'DOUBLE', 'degree_north', 'latitude, degrees north', not_null=True),
    Column('lon', 'DOUBLE', 'degree_east', 'longitude, degrees east', not_null=True),
    SOURCE_FILE,
), primary_key=('port',))

PORTS_REJECTED = Table('ports_rejected', 'rows of ports files refused on import', (
    Column('port', 'VARCHAR', None, 'port name'),
    RAW,
    REASON,
    SOURCE_FILE,
    REJECTED_AT,
))

VESSEL_AVAILABILITY = Table(
    'vessel_availability',
    'when and where each vessel is available for planning, and what it may do', (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    Column('from_utc', 'TIMESTAMP', 'UTC', 'available from (UTC)', not_null=True),
    Column('from_port', 'VARCHAR', None, 'port it is available at', not_null=True),
    Column('until_utc', 'TIMESTAMP', 'UTC', 'must be at until_port by then (UTC) (NULL: open-ended)'),
    Column('until_port', 'VARCHAR', None, 'port where its availability ends'),
    Column('port_hours', 'DOUBLE', 'h', 'average time in port per call, hours'),
    Column('daily_cost', 'DOUBLE', None, 'cost per day out of service, in the currency of the fuel price (e.g. USD)'),
    Column('ports', 'VARCHAR', None, "ports it may call, separated by ';' (NULL: any)"),
    Column('cargo_types', 'VARCHAR', None, "cargo types it may carry, separated by ';' (NULL: any)"),
    Column('laden_speed_kn', 'DOUBLE', 'kn', 'planning speed laden, knots (NULL: design speed)'),
    Column('ballast_speed_kn', 'DOUBLE', 'kn', 'planning speed in ballast, knots (NULL: design speed)'),
    Column('laden_draft_m', 'DOUBLE', 'm',
           'draft laden, metres (fuel per NM from the performance model at this draft)'),
    Column('ballast_draft_m', 'DOUBLE', 'm', 'draft in ballast, metres'),
    SOURCE_FILE,
), primary_key=('imo',))

VESSEL_AVAILABILITY_REJECTED = Table('vessel_availability_rejected', 'rows of availability files refused on import', (
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    RAW,
    REASON,
    SOURCE_FILE,
    REJECTED_AT,
))

CONTRACTS = Table('contracts', 'cargo contracts to plan: cargo, weights, ports and the load window', (
    Column('code', 'VARCHAR', None, 'contract code'),
    Column('cargo_type', 'VARCHAR', None, 'cargo type', not_null=True),
    Column('min_t', 'DOUBLE', 't', 'minimum cargo weight, tonnes', not_null=True),
    Column('max_t', 'DOUBLE', 't', 'maximum cargo weight, tonnes', not_null=True),
    Column('load_port', 'VARCHAR', None, 'port of loading (ports.port)', not_null=True),
    Column('discharge_port', 'VARCHAR', None, 'port of discharge (ports.port)', not_null=True),
    Column('early_utc', 'TIMESTAMP', 'UTC', 'load window opens: earliest start of loading (UTC)', not_null=True),
    Column('late_utc', 'TIMESTAMP', 'UTC', 'load window closes: latest start of loading (UTC)', not_null=True),
    Column('penalty', 'DOUBLE', None,
           'cost of leaving the contract unassigned (e.g. chartered out on the spot market), in the currency of '
           'the fuel price (e.g. USD)'),
    SOURCE_FILE,
), primary_key=('code',))

CONTRACTS_REJECTED = Table('contracts_rejected', 'rows of contracts files refused on import, with the reason', (
    Column('code', 'VARCHAR', None, 'contract code'),
    RAW,
    REASON,
    SOURCE_FILE,
    REJECTED_AT,
))

PORT_DISTANCES = Table(
    'port_distances',
    "sea distance between two ports: length of the shortest sea route over the whole ocean (global sea-route "
    "layer), reused by later plans", (
    Column('port_a', 'VARCHAR', None, 'first port (names in sorted order; the distance holds both ways)'),
    Column('port_b', 'VARCHAR', None, 'second port'),
    Column('lat_a', 'DOUBLE', 'degree_north', 'latitude of port_a used, degrees north'),
    Column('lon_a', 'DOUBLE', 'degree_east', 'longitude of port_a used, degrees east'),
    Column('lat_b', 'DOUBLE', 'degree_north', 'latitude of port_b used, degrees north'),
    Column('lon_b', 'DOUBLE', 'degree_east', 'longitude of port_b used, degrees east'),
    Column('dist_nm', 'DOUBLE', 'NM',
           'shortest sea route clear of land, nautical miles (NULL: no sea route, see reason)'),
    Column('gc_nm', 'DOUBLE', 'NM', 'great-circle distance, nautical miles'),
    Column('reason', 'VARCHAR', None, 'why there is no sea route'),
    Column('computed_at', 'TIMESTAMP', 'UTC', 'when the distance was computed (UTC)'),
    Column('passages', 'VARCHAR', None, "canals and straits the route sails through, in order from port_a, ';'-separated"),
    Column('canal_nm', 'DOUBLE', 'NM', 'length of the route inside canals, nautical miles (sailed in canal_h)'),
    Column('canal_h', 'DOUBLE', 'h', 'hours through the canals on the route, transit and waiting allowance'),
), primary_key=('port_a', 'port_b'))

FLEET_PLANS = Table(
    'fleet_plans',
    'fleet operation plans: which vessel lifts which contract, one row per plan, with its cost items', (
    Column('plan_id', 'VARCHAR', None, 'plan id'),
    Column('created_at', 'TIMESTAMP', 'UTC', 'when the plan was made (UTC)', not_null=True),
    Column('as_of_utc', 'TIMESTAMP', 'UTC', 'planning time (UTC)', not_null=True),
    Column('status', 'VARCHAR', None,
           'active (its voyages are routed) | superseded (a newer plan replaced its unsailed voyages)', not_null=True, allowed=('active', 'superseded')),
    Column('superseded_at', 'TIMESTAMP', 'UTC', 'when a newer plan replaced it (UTC)'),
    Column('solver', 'VARCHAR', None, 'planner used (milp: HiGHS set partitioning)'),
    Column('solve_status', 'VARCHAR', None,
           'optimal (proven) | feasible (best found; gap says how far from optimal at most) | no plan'),
    Column('gap', 'DOUBLE', None, 'proven relative optimality gap (0 when optimal)'),
    Column('runtime_s', 'DOUBLE', 's', 'planner run time, wall-clock seconds (reported only: the search is paced by '
           'work, not by the clock)'),
    Column('n_contracts', 'INTEGER', None, 'contracts planned'),
    Column('n_assigned', 'INTEGER', None, 'contracts given to a vessel'),
    Column('n_unassigned', 'INTEGER', None, 'contracts left (fleet_plan_unassigned says why)'),
    Column('n_vessels_used', 'INTEGER', None, 'vessels with at least one contract'),
    Column('fuel_price', 'DOUBLE', None, 'fuel price per tonne the plan was costed at'),
    Column('fuel_t', 'DOUBLE', 't', 'fuel planned, tonnes (ballast and laden legs)'),
    Column('fuel_cost', 'DOUBLE', None, 'fuel cost, in the currency of the fuel price (e.g. USD)'),
    Column('out_of_service_days', 'DOUBLE', 'day', 'days the used vessels spend in ballast or waiting'),
    Column('out_of_service_cost', 'DOUBLE', None, 'cost of those days, in the currency of the fuel price (e.g. USD)'),
    Column('penalty_cost', 'DOUBLE', None,
           'penalties of the contracts left, in the currency of the fuel price (e.g. USD)'),
    Column('total_cost', 'DOUBLE', None,
           'fuel + out of service + penalties, in the currency of the fuel price (e.g. USD)'),
    Column('gantt_png', 'VARCHAR', None, "picture of each vessel's schedule"),
    Column('stopped_by', 'VARCHAR', None, 'what ended the search: proven optimal | effort: N units spent, gap G % '
           '(the same input and effort give this same plan on any machine) | time limit (safety cap): N s, gap G % '
           '(the wall clock stopped it: may differ from run to run); NULL: planned before it was recorded'),
), primary_key=('plan_id',))

FLEET_PLAN_LEGS = Table('fleet_plan_legs', 'legs of each fleet plan, ballast and laden, with the voyage each became', (
    Column('plan_id', 'VARCHAR', None, 'plan (fleet_plans.plan_id)'),
    Column('imo', 'BIGINT', None, 'IMO number of the vessel'),
    Column('seq', 'INTEGER', None, 'leg number of the vessel, from 0'),
    Column('kind', 'VARCHAR', None,
           'ballast (to a load port or the end port) | laden (load port to discharge port)', not_null=True, allowed=('ballast', 'laden')),
    Column('contract_code', 'VARCHAR', None,
           'contract the leg serves (contracts.code; NULL for the last ballast to the end port)'),
    Column('from_port', 'VARCHAR', None, 'port the leg leaves', not_null=True),
    Column('to_port', 'VARCHAR', None, 'port the leg reaches', not_null=True),
    Column('dist_nm', 'DOUBLE', 'NM', 'sea distance, nautical miles'),
    Column('depart_utc', 'TIMESTAMP', 'UTC', 'planned departure (UTC)', not_null=True),
    Column('arrive_utc', 'TIMESTAMP', 'UTC',
           "required arrival (UTC): laden, the discharge; ballast, the start of loading (the voyage's RTA)", not_null=True),
    Column('fuel_t', 'DOUBLE', 't', 'fuel planned at the planning speed, tonnes'),
    Column('lift_t', 'DOUBLE', 't', 'cargo lifted, tonnes (0 in ballast)'),
    Column('voyage_id', 'VARCHAR', None, 'voyage made of the leg (voyages.voyage_id)'),
), primary_key=('plan_id', 'imo', 'seq'))

FLEET_PLAN_UNASSIGNED = Table('fleet_plan_unassigned', 'contracts a fleet plan leaves unassigned, and why', (
    Column('plan_id', 'VARCHAR', None, 'plan (fleet_plans.plan_id)'),
    Column('contract_code', 'VARCHAR', None, 'contract (contracts.code)'),
    Column('penalty', 'DOUBLE', None, 'its penalty, in the currency of the fuel price (e.g. USD)'),
    Column('reason', 'VARCHAR', None, 'why no vessel lifts it', not_null=True),
), primary_key=('plan_id', 'contract_code'))

TABLES = (PORTS, PORTS_REJECTED, VESSEL_AVAILABILITY, VESSEL_AVAILABILITY_REJECTED, CONTRACTS, CONTRACTS_REJECTED, PORT_DISTANCES, FLEET_PLANS, FLEET_PLAN_LEGS, FLEET_PLAN_UNASSIGNED,)
