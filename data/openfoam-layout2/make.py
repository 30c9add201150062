#!/usr/bin/env python3
"""A second OpenFOAM layout for the diagnosis (session 28): not the development hall.

Room 12.0 x 8.4 x 3.0 m (the `demo` preset's), two rows of 12 racks back to back around
one hot aisle (row A y 2.4-3.6 inlet -y, row B y 4.8-6.0 inlet +y; hot aisle y 3.6-4.8,
return grille over it), a cold aisle along each long wall with 12 tiles (0.6 x 0.6 m,
open fraction 0.25) in front of each row, 4 CRACs (2.25 m3/s rated) at the short walls
feeding one plenum, no containment. Each rack: servers X-01 (u 1) and X-22 (u 22), 21 U
each, types web/db/gpu drawn per server (seed 20261127). True alphas web 0.14, db 0.16,
gpu 0.12 cfm/W; `hall.json` starts at 0.25. Sensors: the `demo` preset's 24 places.
Snapshots t0-t2: the development data's setpoints (per CRAC +0, +0.2, -0.1, +0.1 C) and
fan speeds (0.90 / 1.00 / 0.95), power = type base x rack factor x snapshot scale x
U(0.93, 1.07); the servers draw 89-94 % of the supply.

Cases (the hidden effect is in `truth.json` only):
  ol2-clean         none
  ol2-offset-crac2  crac-2 supplies setpoint - 1.0 C
  ol2-slot-A05      slot through A05 at z 1.0-1.2 m, 0.16 of its flow
  ol2-cutout-A07    floor cutout x 6.0-6.6, y 3.8-4.2 (hot aisle, behind A07), 10 %

Readings: `kalibre simulate --model openfoam` (1000 SIMPLE iterations, the adapter's
defaults) at the true alphas with the effect, plus N(0, 0.15 C) noise (seed 1, Python's
random.Random, CSV row order).

Usage (from the workspace root, OpenFOAM on the PATH; 12 solves of 40-50 s at --np 2 on an idle machine):
  python3 data/openfoam-layout2/make.py [--work DIR]
"""
import copy, csv, json, os, random, subprocess, sys

HERE = os.path.dirname(os.path.abspath(__file__))
WORK = sys.argv[sys.argv.index('--work') + 1] if '--work' in sys.argv else 'out/openfoam-layout2'
KALIBRE = os.environ.get('KALIBRE', 'target/release/kalibre')
TYPES = ['web', 'db', 'gpu']
ALPHA = {'web': 0.14, 'db': 0.16, 'gpu': 0.12}
BASE_W = {'web': 2300, 'db': 2700, 'gpu': 3300}
NOISE_C = 0.15
CASES = {
    'ol2-clean': None,
    'ol2-offset-crac2': {'kind': 'crac_supply_offset', 'crac': 'crac-2', 'offset_c': -1.0},
    'ol2-slot-A05': {'kind': 'rack_recirculation', 'rack': 'A05', 'z_m': [1.0, 1.2], 'fraction': 0.16},
    'ol2-cutout-A07': {'kind': 'bypass', 'position_m': [6.0, 3.8], 'size_m': [0.6, 0.4], 'fraction': 0.1},
}
EXPECTED = {
    'ol2-clean': None,
    'ol2-offset-crac2': 'crac_supply_offset(crac=crac-2)',
    'ol2-slot-A05': 'rack_recirculation(rack=A05)',
    'ol2-cutout-A07': 'bypass(behind_rack=A07)',
}
SENSORS = [  # the demo preset's 24 sensor places
    ('c-A01-11', 2.7, 2.3, 1.1, 'cold'), ('c-A03-17', 3.9, 2.3, 1.7, 'cold'),
    ('c-A04-05', 4.5, 2.3, 0.5, 'cold'), ('c-A05-11', 5.1, 2.3, 1.1, 'cold'),
    ('c-A07-17', 6.3, 2.3, 1.7, 'cold'), ('c-A08-05', 6.9, 2.3, 0.5, 'cold'),
    ('c-A10-11', 8.1, 2.3, 1.1, 'cold'), ('c-A11-17', 8.7, 2.3, 1.7, 'cold'),
    ('h-A03-17', 3.9, 3.9, 1.7, 'hot'), ('h-A04-11', 4.5, 3.9, 1.1, 'hot'),
    ('h-A09-17', 7.5, 3.9, 1.7, 'hot'), ('h-A12-11', 9.3, 3.9, 1.1, 'hot'),
    ('c-B01-05', 2.7, 6.1, 0.5, 'cold'), ('c-B03-11', 3.9, 6.1, 1.1, 'cold'),
    ('c-B04-17', 4.5, 6.1, 1.7, 'cold'), ('c-B06-05', 5.7, 6.1, 0.5, 'cold'),
    ('c-B07-11', 6.3, 6.1, 1.1, 'cold'), ('c-B09-17', 7.5, 6.1, 1.7, 'cold'),
    ('c-B10-05', 8.1, 6.1, 0.5, 'cold'), ('c-B12-11', 9.3, 6.1, 1.1, 'cold'),
    ('h-B03-17', 3.9, 4.5, 1.7, 'hot'), ('h-B05-17', 5.1, 4.5, 1.7, 'hot'),
    ('h-B08-17', 6.9, 4.5, 1.7, 'hot'), ('h-B11-11', 8.7, 4.5, 1.1, 'hot'),
]


def hall_and_operations():
    """The hall (no effect, alphas at 0.25) and the snapshots' operating rows."""
    rng = random.Random(20261127)
    racks = []
    for row, y, inlet in (('A', 2.4, '-y'), ('B', 4.8, '+y')):
        for i in range(12):
            rid = f'{row}{i + 1:02d}'
            lo, hi = TYPES[rng.randrange(3)], TYPES[rng.randrange(3)]
            racks.append({
                'id': rid, 'position_m': [round(2.4 + 0.6 * i, 1), y, 0.0],
                'size_m': [0.6, 1.2, 2.0], 'inlet': inlet, 'units': 42,
                'servers': [{'id': f'{rid}-01', 'type': lo, 'u': 1, 'height_u': 21},
                            {'id': f'{rid}-22', 'type': hi, 'u': 22, 'height_u': 21}]})
    cracs = [{'id': f'crac-{k + 1}', 'position_m': [x, y, 0.0], 'size_m': [1.0, 2.4, 2.0],
              'rated_flow_m3_s': 2.25, 'supply': 'floor'}
             for k, (x, y) in enumerate([(0.0, 1.0), (0.0, 5.2), (11.0, 1.0), (11.0, 5.2)])]
    hall = {
        'schema': 'kalibre.hall/1', 'name': 'ol2-hall', 'room': {'size_m': [12.0, 8.4, 3.0]},
        'server_types': [{'id': t, 'alpha_cfm_per_w': {'initial': 0.25, 'min': 0.01, 'max': 3.0}}
                         for t in TYPES],
        'cracs': cracs,
        'tiles': [{'position_m': [round(2.4 + 0.6 * i, 1), y], 'size_m': [0.6, 0.6],
                   'open_fraction': 0.25} for y in (1.8, 6.0) for i in range(12)],
        'returns': [{'position_m': [2.4, 3.8], 'size_m': [7.2, 0.8]}],
        'racks': racks, 'containment': [],
        'sensors': [{'id': i, 'position_m': [x, y, z], 'aisle': a} for i, x, y, z, a in SENSORS],
        'calibrate': {'alpha': 'per_type'}, 'effects': []}
    rack_factor = {r['id']: rng.uniform(0.8, 1.2) for r in racks}
    rows = []
    for label, setpoint, fan, scale in (('t0', 17.5, 0.90, 0.86), ('t1', 19.0, 1.00, 1.0),
                                        ('t2', 18.2, 0.95, 0.93)):
        for k, c in enumerate(cracs):
            rows.append((label, 'setpoint_c', c['id'], f'{setpoint + [0, 0.2, -0.1, 0.1][k]:.2f}'))
        for c in cracs:
            rows.append((label, 'fan_speed', c['id'], f'{fan:.3f}'))
        for r in racks:
            for s in r['servers']:
                p = round(BASE_W[s['type']] * rack_factor[r['id']] * scale * rng.uniform(0.93, 1.07))
                rows.append((label, 'power_w', s['id'], str(p)))
    return hall, rows


def write_csv(path, rows):
    with open(path, 'w') as f:
        f.write('snapshot,kind,id,value\n')
        for r in rows:
            f.write(','.join(r) + '\n')


def readings(path):
    with open(path) as f:
        return {(r['snapshot'], r['id']): float(r['value'])
                for r in csv.DictReader(f) if r['kind'] == 'sensor_c'}


def main():
    os.makedirs(WORK, exist_ok=True)
    hall, ops = hall_and_operations()
    # `simulate` ignores readings but wants the file's sensor rows.
    placeholder = ops + [(l, 'sensor_c', s[0], '20.00') for l in ('t0', 't1', 't2') for s in SENSORS]
    write_csv(os.path.join(WORK, 'operations.csv'), placeholder)
    for name, effect in CASES.items():
        truth_hall = copy.deepcopy(hall)
        for st in truth_hall['server_types']:
            st['alpha_cfm_per_w']['initial'] = ALPHA[st['id']]
        truth_hall['effects'] = [effect] if effect else []
        th = os.path.join(WORK, f'{name}-truth-hall.json')
        with open(th, 'w') as f:
            json.dump(truth_hall, f, indent=1)
        pred = os.path.join(WORK, f'{name}-openfoam.csv')
        if not os.path.exists(pred):
            subprocess.run([KALIBRE, 'simulate', '--model', 'openfoam', '--np', '2', '--hall', th,
                            '--snapshots', os.path.join(WORK, 'operations.csv'), '--out', pred,
                            '--of-dir', os.path.join(WORK, 'openfoam')], check=True)
        clean = readings(pred)
        rng = random.Random(1)
        rows = list(ops)
        noisy = {}
        for l in ('t0', 't1', 't2'):
            for s in SENSORS:
                noisy[(l, s[0])] = clean[(l, s[0])] + rng.gauss(0.0, NOISE_C)
        # Sensor rows after each snapshot's operating rows, snapshot by snapshot.
        out = []
        for l in ('t0', 't1', 't2'):
            out += [r for r in rows if r[0] == l]
            out += [(l, 'sensor_c', s[0], f'{noisy[(l, s[0])]:.2f}') for s in SENSORS]
        d = os.path.join(HERE, name)
        os.makedirs(d, exist_ok=True)
        with open(os.path.join(d, 'hall.json'), 'w') as f:
            json.dump(dict(hall, name=name), f, indent=1)
        write_csv(os.path.join(d, 'snapshots.csv'), out)
        truth = {
            'dataset': name, 'alpha_true_cfm_per_w': ALPHA, 'alpha_initial_in_hall': 0.25,
            'hidden_effect': effect, 'expected_top': EXPECTED[name],
            'noise': {'distribution': 'gaussian', 'sigma_c': NOISE_C, 'seed': 1,
                      'rng': 'python random.Random(seed).gauss, snapshot by snapshot in sensor order'},
            'openfoam': 'kalibre simulate --model openfoam (1000 SIMPLE iterations, adapter defaults)',
            # As in the development data's truth.json.
            'snapshots': {l: {'sensor_c_noise_free': {s[0]: clean[(l, s[0])] for s in SENSORS}}
                          for l in ('t0', 't1', 't2')},
        }
        with open(os.path.join(d, 'truth.json'), 'w') as f:
            json.dump(truth, f, indent=1)
        print('wrote', d)


if __name__ == '__main__':
    main()
