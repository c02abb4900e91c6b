"""The vertex coder of curve-set format version 2: lattice vertices, predicted and range-coded.

A curve set at a guaranteed tolerance is, at heart, a list of polylines whose vertices may move
by a bounded amount.  This module keeps a subset of each curve's points (a greedy farthest-reach
simplification whose distances are measured to the *quantized* segments, so the rounding is
part of the test, not a margin taken off it), rounds them to a lattice of step ``q``, and codes
the lattice differences with an adaptive binary range coder and small contexts.  Everything
runs in compiled loops over the whole set (one call per set, not per curve or per symbol).

The range coder is LZMA's (``low`` with a carry cache, 32-bit ``range``, renormalised by bytes)
with 15-bit probabilities adapted at a rate that starts fast and settles at ``2**-4`` (0–1 %
fewer bytes than ``2**-5``, 1–3 % fewer than ``2**-6``, on the glyphs of benchmarks/curves.py):
the sets are small (a glyph is a few hundred bytes), so the models must learn in a few dozen
symbols.  It is written here rather than borrowed from ``_blockkernels`` because its contexts
are the curve's own and its stream format must not move when the image coder's does.  All
arithmetic is on integers: every machine writes and reads the same bits.

One function (:func:`_code_set`) both encodes and decodes, so the two cannot drift apart.

Predictors: ``order`` 0–2 predict a step as a multiple of the previous one; 3 and 4 (plane
curves) code the step along and across a predicted direction (docs/curves.md, step 4).

Integers are coded as a sign and a magnitude; the magnitude as its bit length ``k`` (unary,
adaptive, in a context) and then its ``k - 1`` lower bits (adaptive per ``(k, position)``).
Contexts: the bit length of the previous segment's largest coordinate step, and for the second
and later coordinates the bit length of this vertex's first step.
"""

from __future__ import annotations

import numpy as np
from numba import njit

PROB_BITS = 15
PROB_HALF = 1 << (PROB_BITS - 1)
PROB_ONE = 1 << PROB_BITS
RATE_LIMIT = 4
TOP = 1 << 24
MASK32 = (1 << 32) - 1
MAX_BITS = 48  # the largest magnitude coded: 2**48 - 1 lattice steps

# model layout: [probability, count] pairs, grouped
_CLASSES = 17  # context classes of a magnitude's bit length (0 … 16)
_UNARY = MAX_BITS + 1
_KIND_COUNT, _KIND_START = 0, 1  # a curve's first vertex: one context set per coordinate (4)
_FIRST_COORD = _KIND_START + 4
_OTHER_COORD = _FIRST_COORD + _CLASSES
_ALONG = _OTHER_COORD + _CLASSES * 4  # frame predictor: along the predicted direction
_ACROSS = _ALONG + _CLASSES  # and across it
_BULGE = _ACROSS + _CLASSES  # a segment's bulge (version 3): by the previous bulge's size (4)
# and the segment's length (4)
_MAG_KINDS = _BULGE + 16
MAG_BASE = 0
MANT_BASE = MAG_BASE + _MAG_KINDS * _UNARY
MANT_SIZE = (MAX_BITS + 1) * MAX_BITS
SIGN_BASE = MANT_BASE + MANT_SIZE
SIGN_SIZE = 3 * 4 + 4 + 4 + 9  # by the previous residual's sign and the coordinate; first
# vertices; the frame predictor's along (1) and across (3, by the previous across residual);
# bulges (9, by the turns at the segment's two ends)
_SIGN_ALONG = 16
_SIGN_ACROSS = 17
_SIGN_BULGE = 21
#: A bulged segment (curve-set version 3) is decoded as ``BULGE_PARTS`` chords of the parabola
#: through its two vertices whose middle lies ``bulge * step / 2`` off the chord, to the left.
BULGE_PARTS = 8
#: Predictors: 0 the previous vertex, 1 half a step on, 2 a straight continuation; 3 and 4
#: (two dimensions) code a step in the frame of its predicted direction: the previous step's
#: (3) or that direction turned again by the previous turn (4).
FRAME_ORDERS = (3, 4)
#: Refinement tries at most this many positions per vertex (cheapest first), so that its cost
#: stays within a small multiple of the points' count.
_REFINE_TRIES = 48
_FRAME_LIMIT = 1 << 20  # steps longer than this (lattice units) are coded without the frame
FLAG_BASE = SIGN_BASE + SIGN_SIZE
FLAG_SIZE = 4
MODELS = FLAG_BASE + FLAG_SIZE
#: Version 6's models, after every earlier version's (whose priors index below ``MODELS``):
#: the copy flag (by the previous curve's), "as the previous copy" (its distance back and
#: translation), the distance back to the copied curve (unary bit length and one mantissa
#: model), the fraction's bit count and its bits, the translation's lattice vector.
COPY_BASE = MODELS
_COPY_REPEAT = COPY_BASE + 2
_COPY_DISTANCE = _COPY_REPEAT + 1
_COPY_SHIFT = _COPY_DISTANCE + _UNARY + 1
_COPY_FRACTION = _COPY_SHIFT + 2 * (_UNARY + 1)  # the bit counts' models: x, then y
#: the finest fraction of a lattice step by which a copy may be translated: ``2**-COPY_SHIFTS``
COPY_SHIFTS = 6
_COPY_MOVE = _COPY_FRACTION + COPY_SHIFTS  # the translation's lattice vector: x, then y
_COPY_MOVE_SIGN = _COPY_MOVE + 2 * (_UNARY + 1)
ALL_MODELS = _COPY_MOVE_SIGN + 2

#: Version 5's starting probabilities: ``"index:value"`` pairs, ``value / 256`` the
#: probability of a 0 bit (models not listed start at one half).  Learnt on glyphs that
#: benchmarks/curves.py does not measure (other fonts and text: ``python
#: benchmarks/curves.py --train-priors`` prints this table), so that a small set does not pay
#: for learning what every outline shares.
_PRIOR_TABLE = (
    "0:9 1:27 2:89 3:129 4:203 5:229 6:214 49:32 50:29 51:46 52:70 53:82 54:92 55:118 56:136 "
    "57:145 58:192 59:229 98:90 99:75 100:96 101:104 102:116 103:130 104:122 105:161 106:171 "
    "107:176 245:47 246:57 247:92 248:109 249:120 250:164 251:192 252:223 253:161 294:63 "
    "295:110 296:141 297:151 298:153 299:149 343:55 344:84 345:133 346:150 347:136 348:190 "
    "392:33 393:71 394:137 396:153 397:157 398:193 441:36 442:44 443:70 444:130 445:143 446:199 "
    "447:205 490:18 491:33 492:67 493:78 494:150 495:188 496:159 539:9 540:19 541:38 542:88 "
    "543:111 544:179 545:144 588:41 589:10 590:16 591:18 592:94 593:123 594:131 1078:63 1079:58 "
    "1080:75 1081:121 1082:110 1083:139 1084:159 1085:191 1086:201 1127:17 1128:56 1129:72 "
    "1130:95 1131:104 1132:119 1133:131 1134:138 1135:159 1274:103 1275:98 1276:115 1277:145 "
    "1278:111 1279:111 1323:51 1324:102 1325:139 1326:159 1327:132 1372:18 1373:79 1374:124 "
    "1375:196 1376:136 1470:98 1471:87 1472:69 1473:85 1474:150 1475:144 1476:214 1519:101 "
    "1520:101 1521:153 1522:203 1523:188 1568:46 1569:59 1570:146 1571:161 1572:143 1573:152 "
    "1617:11 1618:44 1619:107 1620:143 1621:112 1622:169 1666:87 1667:65 1668:50 1669:59 "
    "1670:86 1671:142 1672:199 1715:66 1716:76 1717:91 1718:118 1719:169 1720:205 1764:79 "
    "1765:95 1766:125 1767:144 1768:165 1813:49 1814:55 1815:115 1816:140 1817:107 1818:119 "
    "1819:196 1862:107 1863:69 1864:81 1865:67 1866:99 1867:89 1868:187 1869:182 1911:47 "
    "1912:72 1913:52 1914:98 1915:155 1916:182 1917:186 1960:60 1961:27 1962:39 1963:120 "
    "1964:150 1965:195 2009:22 2010:59 2011:93 2012:81 2013:132 2014:125 2015:179 2016:135 "
    "2058:122 2059:32 2060:28 2061:46 2062:84 2107:29 2108:75 2109:32 2110:64 2111:110 2112:153 "
    "2113:190 2156:39 2157:58 2158:22 2159:69 2160:100 2161:222 2205:16 2206:43 2207:77 2208:73 "
    "2209:105 2210:175 2211:153 2352:48 2353:61 2354:48 2355:76 2356:53 2357:75 2358:189 "
    "2401:43 2402:33 2403:35 2404:126 2405:123 2406:103 2407:120 2597:9 2598:23 2599:43 2600:21 "
    "2601:76 2602:163 4459:92 4460:76 4461:83 4462:106 4463:117 4464:155 4508:82 4509:56 "
    "4510:94 4511:85 4512:121 4513:150 4514:164 4557:87 4558:54 4559:53 4560:92 4561:113 "
    "4562:122 4563:148 4564:193 4606:86 4607:41 4608:39 4609:83 4611:133 4612:148 4613:180 "
    "4614:187 4655:78 4656:29 4657:52 4658:77 4659:102 4660:137 4661:148 4662:171 4663:200 "
    "4704:65 4705:37 4706:33 4707:74 4708:89 4709:122 4710:155 4711:185 4712:156 4713:222 "
    "4753:61 4754:14 4755:25 4756:56 4757:47 4758:108 4759:129 4760:196 4761:225 4802:82 4803:9 "
    "4804:8 4805:29 4806:26 4807:80 4808:119 4809:141 4810:217 4851:99 4852:15 4853:17 4854:20 "
    "4855:49 4856:103 5243:0 5244:10 5245:38 5246:82 5247:100 5248:147 5249:174 5250:184 "
    "5251:217 5292:15 5293:22 5294:45 5295:82 5296:81 5297:125 5298:141 5299:146 5300:196 "
    "5341:10 5342:18 5343:58 5344:87 5345:106 5346:150 5347:161 5348:213 5390:3 5391:14 5392:39 "
    "5393:83 5394:104 5395:156 5396:177 5397:198 5439:5 5440:14 5441:21 5442:38 5443:87 "
    "5444:142 5445:198 5446:210 5447:204 5488:4 5489:5 5490:7 5491:20 5492:66 5493:102 5494:192 "
    "5495:223 5496:217 5537:12 5538:13 5539:17 5540:38 5541:37 5542:121 5543:167 5544:206 "
    "5545:223 5586:11 5587:12 5588:11 5589:15 5590:19 5591:64 5592:123 5593:171 5594:221 "
    "5635:12 5636:14 5637:12 5638:12 5639:19 5640:29 5641:43 5642:157 5643:210 5684:20 5685:20 "
    "5686:20 5687:20 5688:20 5689:20 5690:44 5691:41 5692:221 6076:203 6125:187 6174:186 "
    "6175:208 6223:192 6224:148 6272:164 6274:209 6275:215 6321:148 6322:125 6323:196 6324:205 "
    "6370:153 6371:138 6372:223 6373:212 6419:169 6420:150 6421:196 6422:204 6469:53 6470:122 "
    "6471:218 6472:223 6517:94 6518:64 6519:117 6520:215 6521:201 6566:95 6567:71 6568:125 "
    "6569:217 6570:207 6615:67 6616:62 6617:136 6618:211 6619:220 6664:150 6665:56 6666:54 "
    "6667:103 6668:216 6669:229 6713:143 6714:58 6715:68 6716:111 6717:195 6718:207 6762:100 "
    "6763:68 6764:91 6765:123 6766:210 6767:205 6811:45 6812:25 6813:60 6814:129 6815:219 "
    "6816:240 6956:142 7004:161 7005:136 7052:166 7053:157 7054:142 7100:157 7101:144 7102:141 "
    "7148:165 7149:156 7150:129 7196:180 7197:162 7198:131 7244:180 7245:156 7246:139 7292:173 "
    "7293:155 7294:113 7340:196 7341:168 7342:134 9212:133 9213:142 9214:108 9215:133 9216:134 "
    "9217:119 9224:196 9228:161 9229:139 9230:135 9231:120 9233:247 9234:183 9235:158 9236:183 "
    "9237:180 9239:192 9240:131 9241:6 9242:255 "
)
#: Version 6's copy models' starting probabilities (as :data:`_PRIOR_TABLE`; their indices are
#: from :data:`COPY_BASE`, which no earlier version codes), learnt on the same training
#: glyphs coded as version 6 (``python benchmarks/curves.py --train-priors``, its second line).
_COPY_PRIOR_TABLE = (
    "9245:199 9246:94 9247:151 9248:12 9249:17 9250:12 9251:20 9252:74 9253:134 9254:211 9255:197 "
    "9297:125 9298:84 9299:92 9300:174 9301:218 9347:158 9348:240 9349:12 9350:243 9397:116 "
    "9398:16 9399:123 9400:124 9401:118 9402:156 9403:131 9404:20 9405:29 9406:35 9407:68 9408:84 "
    "9409:88 9410:121 9411:123 9412:136 9413:200 9414:213 9453:131 9454:239 9455:42 9456:50 "
    "9457:74 9458:82 9459:90 9460:102 9503:135 9504:202 9505:42 "
)
#: A model with a prior starts at this adaptation count (its first updates move it less).
PRIOR_COUNT = 2


def _parse_priors(table: str) -> np.ndarray:
    models = np.empty(2 * ALL_MODELS, dtype=np.int64)
    models[0::2] = PROB_HALF
    models[1::2] = 0
    for pair in table.split():
        index, value = (int(x) for x in pair.split(":"))
        models[2 * index] = (2 * value + 1) << (PROB_BITS - 9)
        models[2 * index + 1] = PRIOR_COUNT
    return models


def initial_models(priors: bool) -> np.ndarray:
    """The coder's starting models: every probability one half, or version 5's priors."""
    return (_PRIORS if priors else _HALVES).copy()


def trained_table(
    states: list[np.ndarray], least: int = 4, first: int = 0, stop: int = MODELS
) -> str:
    """The prior table (:data:`_PRIOR_TABLE`'s form) from the final models of coded sets: per
    model of ``first`` up to ``stop`` (version 5's by default; version 6's copy models from
    :data:`COPY_BASE` to :data:`ALL_MODELS`), the mean probability over the sets that used it,
    where at least ``least`` did."""
    stack = np.stack(states)[:, 2 * first : 2 * stop]
    used = stack[:, 1::2] > 0
    mean = np.where(used, stack[:, 0::2], 0).sum(axis=0) / np.maximum(used.sum(axis=0), 1)
    pairs = []
    for index in (first + np.flatnonzero(used.sum(axis=0) >= least)).tolist():
        value = int(np.clip(mean[index - first] / (1 << (PROB_BITS - 8)), 0, 255))
        if value != 127 and value != 128:
            pairs.append(f"{index}:{value}")
    return " ".join(pairs)


# state fields
_LOW, _RANGE, _CACHE, _CSIZE, _POS, _CODE = 0, 1, 2, 3, 4, 5


@njit(cache=True, nogil=True, inline="always")
def _shift_low(st, out):
    low = st[_LOW]
    if low < 0xFF000000 or low > MASK32:
        carry = low >> 32
        temp = st[_CACHE]
        while True:
            pos = st[_POS]
            if pos < len(out):
                out[pos] = (temp + carry) & 0xFF
            st[_POS] = pos + 1
            temp = 0xFF
            st[_CSIZE] -= 1
            if st[_CSIZE] == 0:
                break
        st[_CACHE] = (low >> 24) & 0xFF
    st[_CSIZE] += 1
    st[_LOW] = (low & 0x00FFFFFF) << 8


@njit(cache=True, nogil=True, inline="always")
def _next_byte(st, data):
    pos = st[_POS]
    st[_POS] = pos + 1
    return data[pos] if pos < len(data) else 0


@njit(cache=True, nogil=True)
def _bit(st, buf, models, ctx, bit, decoding):
    """Code ``bit`` (encoding) or return the decoded bit, with the adaptive model ``ctx``."""
    p = models[2 * ctx]
    bound = (st[_RANGE] >> PROB_BITS) * p
    if decoding:
        if st[_CODE] < bound:
            st[_RANGE] = bound
            bit = 0
        else:
            st[_CODE] -= bound
            st[_RANGE] -= bound
            bit = 1
        while st[_RANGE] < TOP:
            st[_RANGE] = (st[_RANGE] << 8) & MASK32
            st[_CODE] = ((st[_CODE] << 8) | _next_byte(st, buf)) & MASK32
    else:
        if bit == 0:
            st[_RANGE] = bound
        else:
            st[_LOW] += bound
            st[_RANGE] -= bound
        while st[_RANGE] < TOP:
            st[_RANGE] = (st[_RANGE] << 8) & MASK32
            _shift_low(st, buf)
    count = models[2 * ctx + 1]
    rate = min(count + 1, RATE_LIMIT)
    if bit == 0:
        p += (PROB_ONE - p) >> rate
    else:
        p -= p >> rate
    models[2 * ctx] = p
    if count < RATE_LIMIT:
        models[2 * ctx + 1] = count + 1
    return bit


@njit(cache=True, nogil=True, inline="always")
def _bit_length(value):
    k = 0
    while value > 0:
        value >>= 1
        k += 1
    return k


@njit(cache=True, nogil=True, inline="always")
def _unary_length(st, buf, models, base, value, decoding):
    """Code the bit length ``k`` of ``value >= 0`` in unary with models ``base + i``; return it."""
    k = 0 if decoding else _bit_length(value)
    if decoding:
        while k < MAX_BITS and _bit(st, buf, models, base + k, 0, True):
            k += 1
    else:
        for i in range(k):
            _bit(st, buf, models, base + i, 1, False)
        if k < MAX_BITS:
            _bit(st, buf, models, base + k, 0, False)
    return k


@njit(cache=True, nogil=True)
def _magnitude(st, buf, models, kind, value, decoding):
    """Code a magnitude ``value >= 0`` in the unary context set ``kind``; return it."""
    k = _unary_length(st, buf, models, MAG_BASE + kind * _UNARY, value, decoding)
    if k <= 1:
        return k
    out = 1
    mbase = MANT_BASE + k * MAX_BITS
    for i in range(k - 2, -1, -1):
        position = k - 2 - i
        ctx = mbase + min(position, MAX_BITS - 1)
        if position >= 2:  # below the two leading bits: nearly uniform, one shared model
            ctx = mbase + 2
        bit = _bit(st, buf, models, ctx, (value >> i) & 1, decoding)
        out = (out << 1) | bit
    return out


@njit(cache=True, nogil=True)
def _plain_magnitude(st, buf, models, base, value, decoding):
    """A magnitude ``value >= 0``: its bit length in unary (models ``base + k``), the bits
    below the leading one with the one model ``base + _UNARY`` (version 6's copies)."""
    k = _unary_length(st, buf, models, base, value, decoding)
    if k <= 1:
        return k
    out = 1
    for i in range(k - 2, -1, -1):
        out = (out << 1) | _bit(st, buf, models, base + _UNARY, (value >> i) & 1, decoding)
    return out


@njit(cache=True, nogil=True)
def _signed(st, buf, models, kind, sign_ctx, value, decoding):
    magnitude = _magnitude(st, buf, models, kind, abs(value), decoding)
    if magnitude == 0:
        return 0
    negative = _bit(st, buf, models, SIGN_BASE + sign_ctx, 1 if value < 0 else 0, decoding)
    return -magnitude if negative else magnitude


@njit(cache=True, nogil=True, inline="always")
def _class(k):
    return min(k, _CLASSES - 1)


@njit(cache=True, nogil=True)
def _frame(lattice, v, first, order):
    """The predicted direction of the step into vertex ``v`` (two dimensions): ``(x, y)`` in
    lattice units, ``(0, 0)`` where there is none (the curve's first two steps, or steps too
    long for exact integer arithmetic)."""
    if v - first < 2:
        return 0, 0
    sx = lattice[v - 1, 0] - lattice[v - 2, 0]
    sy = lattice[v - 1, 1] - lattice[v - 2, 1]
    if max(abs(sx), abs(sy)) >= _FRAME_LIMIT:
        return 0, 0
    if order == 4 and v - first >= 3:
        px = lattice[v - 2, 0] - lattice[v - 3, 0]
        py = lattice[v - 2, 1] - lattice[v - 3, 1]
        if 0 < max(abs(px), abs(py)) < 1 << 10 and max(abs(sx), abs(sy)) < 1 << 10:
            # s turned by the angle from p to s: s * s * conj(p), as Gaussian integers
            ax, ay = sx * sx - sy * sy, 2 * sx * sy
            return ax * px + ay * py, ay * px - ax * py
    return sx, sy


@njit(cache=True, nogil=True, inline="always")
def _to_frame(zx, zy, x, y):
    """``(x, y)`` in the signed-permutation frame that puts ``(zx, zy)`` in the first octant
    (``zx >= zy >= 0``): a bijection of the integer lattice."""
    if zx < 0:
        x = -x
    if zy < 0:
        y = -y
    if abs(zy) > abs(zx):
        return y, x
    return x, y


@njit(cache=True, nogil=True, inline="always")
def _from_frame(zx, zy, u, w):
    if abs(zy) > abs(zx):
        u, w = w, u
    if zx < 0:
        u = -u
    if zy < 0:
        w = -w
    return u, w


@njit(cache=True, nogil=True, inline="always")
def _across_prediction(zx, zy, u):
    """The across coordinate predicted for the along one ``u``: on the predicted line."""
    a, b = max(abs(zx), abs(zy)), min(abs(zx), abs(zy))
    if a == 0 or abs(u) >= _FRAME_LIMIT:
        return 0
    return (2 * u * b + a) // (2 * a)


@njit(cache=True, nogil=True)
def _code_set(
    buf,
    st,
    lattice,
    counts,
    closed,
    repeated,
    closed_mode,
    d,
    order,
    decoding,
    bulges,
    bulged,
    from_last,
    models,
    copying,
    sources,
    fractions,
):
    """Code (or decode into ``lattice``, ``counts``, ``closed``, ``repeated``) a whole set.

    ``lattice`` holds the vertices of all curves, one after another, ``(total, d)`` int64.
    ``order`` is the predictor: each step is predicted as ``(order * previous step) >> 1``
    (0: the previous vertex; 2: a straight continuation; 1: half way), and the residual coded.
    With ``bulged`` (version 3), each segment's bulge follows the vertex that ends it (a
    closed curve's closing segment after its last vertex), kept in ``bulges`` at the row of
    the segment's end (the closing segment's at the curve's first row).
    With ``from_last`` (version 4), a curve's first vertex is coded from the previous curve's
    last vertex rather than its first.
    With ``copying`` (version 6), each curve after the first has a flag: a *copy* of curve
    ``sources[c]`` (an earlier one), translated: a bit "as the previous copy" (the same
    distance back and translation; after the first copy), else the distance back, its first
    vertex's lattice step from the source's first vertex, and ``fractions[c] = (k_0, f_0, k_1,
    f_1, …)``: a translation by ``f_j / 2**k_j`` of a lattice step more.  Its count, vertices
    and bulges are the source's, moved with its first vertex.  ``sources`` is -1 for a curve
    coded in full.
    Returns the number of vertices (decoding: those written; -1 if the stream declares more
    than ``lattice`` holds).
    """
    plain = order if order < 3 else 0  # the frame predictors' steps without a frame
    start = np.zeros(d, dtype=np.int64)
    previous_step = np.zeros(d, dtype=np.int64)
    previous_residual = np.zeros(d, dtype=np.int64)
    at = 0
    limit = len(lattice)
    rows = np.zeros(len(counts) + 1, dtype=np.int64)  # each curve's first row
    copied = 0
    last_back = -1  # the previous copy's distance back (-1: none yet)
    last_move = np.zeros(3 * d, dtype=np.int64)  # its translation: lattice vector, fractions
    for c in range(len(counts)):
        rows[c] = at
        if closed_mode == 2:
            closed[c] = _bit(st, buf, models, FLAG_BASE, closed[c], decoding)
        if closed[c]:
            repeated[c] = _bit(st, buf, models, FLAG_BASE + 1, repeated[c], decoding)
        source = -1
        repeat = 0
        if copying and c > 0:
            flag = _bit(st, buf, models, COPY_BASE + copied, sources[c] >= 0, decoding)
            copied = flag
            if flag:
                back = 0 if decoding else c - 1 - sources[c]
                if last_back >= 0:  # the previous copy's distance back and translation?
                    same = 0
                    if not decoding and back == last_back:
                        first = rows[sources[c]]
                        same = 1
                        for j in range(d):
                            if lattice[at, j] - lattice[first, j] != last_move[j]:
                                same = 0
                        for j in range(2 * d):
                            if fractions[c, j] != last_move[d + j]:
                                same = 0
                    repeat = _bit(st, buf, models, _COPY_REPEAT, same, decoding)
                if repeat:
                    back = last_back
                else:
                    back = _plain_magnitude(st, buf, models, _COPY_DISTANCE, back, decoding)
                if back > c - 1:
                    return -1
                source = c - 1 - back
                last_back = back
                if decoding:
                    sources[c] = source
            elif decoding:
                sources[c] = -1
        if source >= 0:
            m = counts[source]
        else:
            m = _magnitude(st, buf, models, _KIND_COUNT, counts[c] - 1, decoding) + 1
        if decoding:
            if m > limit - at:
                return -1
            counts[c] = m
        if source >= 0:
            # a translated copy: the translation from its source's first vertex (a lattice
            # vector and a fraction of a step), then the source's shape
            first = rows[source]
            if repeat:
                for j in range(d):
                    lattice[at, j] = lattice[first, j] + last_move[j]
                for j in range(2 * d):
                    fractions[c, j] = last_move[d + j]
            else:
                for j in range(d):
                    # x from the previous curve's first vertex (text runs on: the nearest
                    # start), the others from the source's (a copy on the same baseline: 0)
                    base = rows[c - 1] if j == 0 else first
                    value = 0 if decoding else lattice[at, j] - lattice[base, j]
                    size = _plain_magnitude(
                        st, buf, models, _COPY_MOVE + min(j, 1) * (_UNARY + 1), abs(value), decoding
                    )
                    if size and _bit(
                        st, buf, models, _COPY_MOVE_SIGN + min(j, 1), value < 0, decoding
                    ):
                        size = -size
                    lattice[at, j] = lattice[base, j] + size
                for j in range(d):  # each coordinate's fraction: its bit count, its bits
                    shift = 0 if decoding else fractions[c, 2 * j]
                    shift = _plain_magnitude(
                        st, buf, models, _COPY_SHIFT + min(j, 1) * (_UNARY + 1), shift, decoding
                    )
                    if shift > COPY_SHIFTS:
                        return -1
                    fractions[c, 2 * j] = shift
                    value = 0
                    for i in range(shift - 1, -1, -1):
                        bit = _bit(
                            st,
                            buf,
                            models,
                            _COPY_FRACTION + i,
                            (fractions[c, 2 * j + 1] >> i) & 1,
                            decoding,
                        )
                        value = (value << 1) | bit
                    fractions[c, 2 * j + 1] = value
            for j in range(d):
                last_move[j] = lattice[at, j] - lattice[first, j]
                start[j] = lattice[at, j]
            for j in range(2 * d):
                last_move[d + j] = fractions[c, j]
            for v in range(1, m):
                for j in range(d):
                    lattice[at + v, j] = lattice[at, j] + lattice[first + v, j] - lattice[first, j]
                if bulged:
                    bulges[at + v] = bulges[first + v]
            if bulged:
                bulges[at] = bulges[first]
            at += m
            continue
        # the first vertex: a step from the previous curve's first (or last) vertex
        for j in range(d):
            if from_last and at > 0:
                start[j] = lattice[at - 1, j]
            value = 0 if decoding else lattice[at, j] - start[j]
            value = _signed(
                st, buf, models, _KIND_START + min(j, 3), 12 + min(j, 3), value, decoding
            )
            if decoding:
                lattice[at, j] = start[j] + value
            start[j] = lattice[at, j]
        length_class = _class(_bit_length(0))
        for j in range(d):
            previous_step[j] = 0
            previous_residual[j] = 0
        across_sign = 0
        for v in range(at + 1, at + m):
            if order >= 3 and d == 2:
                zx, zy = _frame(lattice, v, at, order)
                if zx != 0 or zy != 0:
                    u, w = 0, 0
                    if not decoding:
                        u, w = _to_frame(
                            zx,
                            zy,
                            lattice[v, 0] - lattice[v - 1, 0],
                            lattice[v, 1] - lattice[v - 1, 1],
                        )
                    u = _signed(st, buf, models, _ALONG + length_class, _SIGN_ALONG, u, decoding)
                    predicted = _across_prediction(zx, zy, u)
                    kind = _ACROSS + _class(_bit_length(abs(u)))
                    sign_ctx = _SIGN_ACROSS + 1 + across_sign
                    r = _signed(st, buf, models, kind, sign_ctx, w - predicted, decoding)
                    across_sign = (r > 0) - (r < 0)
                    w = predicted + r
                    x, y = _from_frame(zx, zy, u, w)
                    if decoding:
                        lattice[v, 0] = lattice[v - 1, 0] + x
                        lattice[v, 1] = lattice[v - 1, 1] + y
                    length_class = _class(_bit_length(max(abs(x), abs(y))))
                    continue
            first_class = 0
            largest = 0
            for j in range(d):
                if j == 0:
                    kind = _FIRST_COORD + length_class
                else:
                    kind = _OTHER_COORD + length_class * 4 + min(first_class, 3)
                r = previous_residual[j]
                sign_ctx = 1 + (r > 0) - (r < 0) + 3 * min(j, 3)
                predicted = lattice[v - 1, j] + ((plain * previous_step[j]) >> 1)
                value = 0 if decoding else lattice[v, j] - predicted
                value = _signed(st, buf, models, kind, sign_ctx, value, decoding)
                if decoding:
                    lattice[v, j] = predicted + value
                previous_step[j] = lattice[v, j] - lattice[v - 1, j]
                previous_residual[j] = value
                k = _bit_length(abs(value))
                if j == 0:
                    # how far the first coordinate's size is below the segment's (0 … 3)
                    first_class = max(0, min(3, length_class - k + 1))
                largest = max(largest, abs(previous_step[j]))
            length_class = _class(_bit_length(largest))
        if bulged:  # the curve's bulges, in order; a closed curve's closing one last
            bulge_class, bulge_sign = 0, 0
            for row in range(at + 1, at + m):
                bulge_class, bulge_sign = _bulge(
                    st,
                    buf,
                    models,
                    bulges,
                    row,
                    row - 1,
                    lattice,
                    at,
                    m,
                    closed[c],
                    bulge_class,
                    bulge_sign,
                    decoding,
                )
            if closed[c] and m > 1:
                _bulge(
                    st,
                    buf,
                    models,
                    bulges,
                    at,
                    at + m - 1,
                    lattice,
                    at,
                    m,
                    closed[c],
                    bulge_class,
                    bulge_sign,
                    decoding,
                )
            else:
                bulges[at] = 0
        at += m
    return at


@njit(cache=True, nogil=True, inline="always")
def _turn(lattice, a, b, c):
    """The sign of the turn at ``b`` from ``a`` to ``c`` (+1 left, -1 right, 0 straight), for
    steps short enough for exact products (0 beyond)."""
    ux, uy = lattice[b, 0] - lattice[a, 0], lattice[b, 1] - lattice[a, 1]
    vx, vy = lattice[c, 0] - lattice[b, 0], lattice[c, 1] - lattice[b, 1]
    if max(abs(ux), abs(uy), abs(vx), abs(vy)) >= _FRAME_LIMIT:
        return 0
    cross = ux * vy - uy * vx
    return (cross > 0) - (cross < 0)


@njit(cache=True, nogil=True)
def _bulge(
    st, buf, models, bulges, row, before, lattice, at, m, ring, bulge_class, bulge_sign, decoding
):
    """Code the bulge of the segment from row ``before`` to ``row`` (of the curve at rows
    ``at … at + m - 1``); the next bulge's contexts.  Context: the previous bulge's size and
    the segment's (a sagitta grows with the square of the chord); for its sign, the turns at
    both its ends (an arc bulges to the side it turns away from)."""
    longest = max(
        abs(lattice[row, 0] - lattice[before, 0]), abs(lattice[row, 1] - lattice[before, 1])
    )
    kind = _BULGE + bulge_class + 4 * min(3, _bit_length(longest) // 2)
    earlier = before - 1 if before > at else (at + m - 1 if ring else -1)
    later = row + 1 if row < at + m - 1 else (at if ring else -1)
    turn_in = _turn(lattice, earlier, before, row) if earlier >= 0 else 0
    turn_out = _turn(lattice, before, row, later) if later >= 0 else 0
    sign_ctx = _SIGN_BULGE + 3 * (1 + turn_in) + 1 + turn_out
    value = _signed(st, buf, models, kind, sign_ctx, bulges[row], decoding)
    bulges[row] = value
    return min(3, _bit_length(abs(value))), (value > 0) - (value < 0)


@njit(cache=True, nogil=True)
def _finish_stream(st, out):
    """Flush with the fewest bytes: pick the value in [low, low + range) with most low zeros."""
    low = st[_LOW]
    high = low + st[_RANGE] - 1
    for shift in range(32, -1, -1):
        candidate = (high >> shift) << shift
        if candidate >= low:
            st[_LOW] = candidate
            break
    for _ in range(5):
        _shift_low(st, out)


def encode_set(
    lattice: np.ndarray,
    counts: np.ndarray,
    closed: np.ndarray,
    repeated: np.ndarray,
    closed_mode: int,
    order: int = 0,
    bulges: np.ndarray | None = None,
    from_last: bool = False,
    priors: bool = False,
    models: np.ndarray | None = None,
    sources: np.ndarray | None = None,
    fractions: np.ndarray | None = None,
) -> bytes:
    """The range-coded stream of a set of lattice curves (see :func:`decode_set`); with
    ``bulges`` (one per vertex row: the bulge of the segment ending there), version 3's;
    ``from_last`` (version 4) codes a curve's first vertex from the previous curve's last;
    ``sources`` and ``fractions`` (version 6: both or neither) the copies, as in
    :func:`_code_set` (the copies' rows of ``lattice`` and ``bulges`` must be their sources',
    moved)."""
    copying = sources is not None
    sources = np.full(len(counts), -1, dtype=np.int64) if sources is None else sources
    if fractions is None:
        fractions = np.zeros((len(counts), 2 * lattice.shape[1]), dtype=np.int64)
    d = lattice.shape[1]
    bulged = bulges is not None
    bulges = np.zeros(len(lattice), dtype=np.int64) if bulges is None else bulges
    capacity = 64 + 16 * lattice.size + 8 * len(counts)
    out = np.zeros(capacity, dtype=np.uint8)
    st = np.array([0, MASK32, 0, 1, 0, 0], dtype=np.int64)
    models = initial_models(priors) if models is None else models
    _code_set(
        out,
        st,
        np.ascontiguousarray(lattice, dtype=np.int64),
        np.ascontiguousarray(counts, dtype=np.int64),
        np.ascontiguousarray(closed, dtype=np.int64),
        np.ascontiguousarray(repeated, dtype=np.int64),
        closed_mode,
        d,
        order,
        False,
        np.ascontiguousarray(bulges, dtype=np.int64),
        bulged,
        bool(from_last),
        models,
        copying,
        np.ascontiguousarray(sources, dtype=np.int64),
        np.ascontiguousarray(fractions, dtype=np.int64),
    )
    _finish_stream(st, out)
    size = int(st[_POS])
    if size > capacity or out[0] != 0:
        msg = "the curve coder overflowed its buffer"  # cannot happen: 16 B per value is ample
        raise RuntimeError(msg)
    data = bytes(out[1:size])  # the first byte of an LZMA-style stream is always 0
    return data.rstrip(b"\0")  # the decoder reads zeros past the end


def decode_set(
    data: bytes,
    count: int,
    d: int,
    closed_mode: int,
    all_closed: bool,
    max_vertices: int,
    order: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Decode ``count`` curves of dimension ``d``: (lattice, counts, closed, repeated).

    None if the stream declares more than ``max_vertices`` vertices in all.
    """
    result = decode_bulged_set(data, count, d, closed_mode, all_closed, max_vertices, order, False)
    return None if result is None else result[:4]


def decode_bulged_set(
    data: bytes,
    count: int,
    d: int,
    closed_mode: int,
    all_closed: bool,
    max_vertices: int,
    order: int,
    bulged: bool,
    from_last: bool = False,
    priors: bool = False,
    copies: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """As :func:`decode_set`, and the bulges (zeros unless ``bulged``: version 3);
    ``from_last`` as in :func:`encode_set` (version 4).  With ``copies`` (version 6: an
    array ``(count, 2 d + 1)``), each curve's source (-1 for none) and fraction are written to
    its rows, as :func:`_code_set` gives them."""
    buf = np.frombuffer(bytes(data), dtype=np.uint8).copy()  # one compiled signature
    st = np.array([0, MASK32, 0, 1, 0, 0], dtype=np.int64)
    code = 0
    for _ in range(4):
        code = (code << 8) | (int(buf[st[_POS]]) if st[_POS] < len(buf) else 0)
        st[_POS] += 1
    st[_CODE] = code
    lattice = np.zeros((max_vertices, d), dtype=np.int64)
    counts = np.zeros(count, dtype=np.int64)
    closed = np.full(count, 1 if all_closed else 0, dtype=np.int64)
    repeated = np.zeros(count, dtype=np.int64)
    bulges = np.zeros(max_vertices, dtype=np.int64)
    sources = np.full(count, -1, dtype=np.int64)
    fractions = np.zeros((count, 2 * d), dtype=np.int64)
    total = _code_set(
        buf,
        st,
        lattice,
        counts,
        closed,
        repeated,
        closed_mode,
        d,
        order,
        True,
        bulges,
        bulged,
        bool(from_last),
        initial_models(priors),
        copies is not None,
        sources,
        fractions,
    )
    if total < 0:
        return None
    if copies is not None:
        copies[:, 0] = sources
        copies[:, 1:] = fractions
    return lattice[:total], counts, closed, repeated, bulges[:total]


# --- the encoder's geometry: simplification against quantized segments, and the check --------


@njit(cache=True, nogil=True)
def _segment_distance(points, k, nodes, a, b, d):
    """Distance from ``points[k]`` to the segment ``nodes[a]``–``nodes[b]``."""
    length2 = 0.0
    dot = 0.0
    for j in range(d):
        ab = nodes[b, j] - nodes[a, j]
        length2 += ab * ab
        dot += (points[k, j] - nodes[a, j]) * ab
    t = 0.0
    if length2 > 0.0:
        t = min(1.0, max(0.0, dot / length2))
    gap2 = 0.0
    for j in range(d):
        g = points[k, j] - (nodes[a, j] + t * (nodes[b, j] - nodes[a, j]))
        gap2 += g * g
    return np.sqrt(gap2)


@njit(cache=True, nogil=True)
def _span_fits(points, decoded, first, n, a, b, tolerance, d):
    """The largest distance from the points strictly between ``a`` and ``b`` (ring indices)
    to the decoded segment ``a``–``b``, stopping early once above ``tolerance``."""
    worst = 0.0
    end = first + (b % n)
    for k in range(a + 1, b):
        gap = _segment_distance(points, first + (k % n), decoded, first + (a % n), end, d)
        if gap > worst:
            worst = gap
            if worst > tolerance:
                break
    return worst


@njit(cache=True, nogil=True)
def reach_set(points, decoded, offsets, closed, starts, tolerance, window):
    """Greedy farthest reach on each curve, distances to the *decoded* (lattice) segments.

    From each kept point the next one is the farthest (within ``window`` points) whose
    segment keeps every point between within ``tolerance``, found by galloping and bisection
    (then a few points beyond the first miss), so the cost is ``O(L log L)`` for a segment of
    ``L`` points: linear-ish whatever the shape.  A closed
    curve starts at ring index ``starts[c]`` (the caller rotates it there).  Greedy reach
    keeps fewer vertices than Douglas–Peucker (which splits at the worst point, not where a
    segment could end).  Returns a mask of the kept points.
    """
    total, d = points.shape
    keep = np.zeros(total, dtype=np.bool_)
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        if n == 0:
            continue
        ring = n + 1 if closed[c] and n > 2 else n
        a = starts[c] if ring > n else 0
        last = a + ring - 1  # ring index of the end (the start again on a closed curve)
        keep[first + (a % n)] = True
        keep[first + (last % n)] = True
        while a < last:
            top = min(last, a + window)
            # gallop: spans of 2, 4, 8, … points while they fit, then bisect the last gap
            best = a + 1
            span = 2
            fail = top + 1
            while a + span <= top:
                if _span_fits(points, decoded, first, n, a, a + span, tolerance, d) <= tolerance:
                    best = a + span
                    span *= 2
                else:
                    fail = a + span
                    break
            if fail > top and best < top:
                if _span_fits(points, decoded, first, n, a, top, tolerance, d) <= tolerance:
                    best = top
                else:
                    fail = top
            while fail - best > 1:
                middle = (best + fail) // 2
                if _span_fits(points, decoded, first, n, a, middle, tolerance, d) <= tolerance:
                    best = middle
                else:
                    fail = middle
            # a span may fit again past a miss (the curve comes back): look a few points on
            b = best + 2
            while b <= min(top, best + 4):
                if _span_fits(points, decoded, first, n, a, b, tolerance, d) <= tolerance:
                    best = b
                b += 1
            keep[first + (best % n)] = True
            a = best
    return keep


@njit(cache=True, nogil=True)
def optimal_set(points, decoded, offsets, closed, starts, tolerance, window, greedy):
    """Fewest vertices on each curve (Imai–Iri): a shortest path in the graph whose edges are
    the spans that keep every point between within ``tolerance`` of the *decoded* segment
    (:func:`reach_set`'s test), each span at most ``window`` points long, tested exactly.

    Greedy farthest reach is one path in that graph, so the result never has more vertices;
    on the glyphs of benchmarks/curves.py it has 1–5 % fewer at coarse tolerances (a span
    that stops short of the farthest reach can let the next one go much farther).  A span is
    tested only where it would shorten the path to its end, so on long smooth stretches few
    are; where a curve's tests would still exceed a work budget linear in its points
    (``256 n`` points visited, plus a constant), it keeps ``greedy``'s vertices (the mask of
    :func:`reach_set` from the same starts).  Returns a mask of the kept points.
    """
    total = points.shape[0]
    d = points.shape[1]
    keep = np.zeros(total, dtype=np.bool_)
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        if n == 0:
            continue
        ring = n + 1 if closed[c] and n > 2 else n
        origin = starts[c] if ring > n else 0
        last = ring - 1  # path positions 0 … last, point (origin + position) % n
        dist = np.full(last + 1, 1 << 40, dtype=np.int64)
        previous = np.full(last + 1, -1, dtype=np.int64)
        dist[0] = 0
        budget = 256 * n + (1 << 16)
        for a in range(last):
            if budget < 0:
                break
            top = min(last, a + window)
            for b in range(a + 1, top + 1):
                if dist[a] + 1 >= dist[b]:
                    continue
                budget -= b - a
                gap = _span_fits(points, decoded, first, n, origin + a, origin + b, tolerance, d)
                if gap <= tolerance:
                    dist[b] = dist[a] + 1
                    previous[b] = a
        if budget < 0:
            for i in range(first, stop):
                keep[i] = greedy[i]
            continue
        at = last
        while at >= 0:
            keep[first + ((origin + at) % n)] = True
            at = previous[at]
    return keep


@njit(cache=True, nogil=True)
def _to_original(query, q, points, first, n, closed, lo, hi, d):
    """Distance from ``query[q]`` to the original segments ``lo … hi - 1`` (ring-wise)."""
    best = np.inf
    if n == 1:
        return _segment_distance(query, q, points, first, first, d)
    for s in range(lo, hi):
        a = s % n if closed else s
        b = (s + 1) % n if closed else s + 1
        if not closed and b >= n:
            b = n - 1
        best = min(best, _segment_distance(query, q, points, first + a, first + b, d))
    return best


@njit(cache=True, nogil=True)
def _near_original(query, q, points, first, n, closed, lo, hi, d, tolerance):
    """Whether ``query[q]`` lies within ``tolerance`` of the original segments ``lo … hi - 1``
    (:func:`_to_original`, stopping at the first segment near enough)."""
    if n == 1:
        return _segment_distance(query, q, points, first, first, d) <= tolerance
    for s in range(lo, hi):
        a = s % n if closed else s
        b = (s + 1) % n if closed else s + 1
        if not closed and b >= n:
            b = n - 1
        if _segment_distance(query, q, points, first + a, first + b, d) <= tolerance:
            return True
    return False


@njit(cache=True, nogil=True)
def check_set(points, offsets, closed, keep, decoded):
    """The largest deviation, both ways, of each curve (an upper bound of the true one).

    ``decoded`` holds the decoded vertices (those of the kept points, in order, as the decoder
    gives them).  Each original point strictly between two kept points is measured to the
    decoded segment between them; a kept point to the nearer of its two decoded segments; each
    decoded vertex to the original segments between the kept points before and after it.  Each
    is a minimum over part of a polyline, so no smaller than the true distance.
    """
    d = points.shape[1]
    worst = np.zeros(len(offsets) - 1)
    at = 0
    index = np.empty(points.shape[0] + 1, dtype=np.int64)
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        m = 0
        for i in range(n):
            if keep[first + i]:
                index[m] = i
                m += 1
        ring = bool(closed[c]) and n > 2
        largest = 0.0
        for v in range(m):
            here = at + v
            # the segment after vertex v, and the original points it covers
            if v + 1 < m:
                after, k_after = at + v + 1, index[v + 1]
            elif ring:
                after, k_after = at, n
            else:
                after, k_after = -1, n
            # the kept point itself
            gap = _segment_distance(points, first + index[v], decoded, here, here, d)
            if after >= 0:
                gap = min(gap, _segment_distance(points, first + index[v], decoded, here, after, d))
            if v > 0 or ring:
                before = here - 1 if v > 0 else at + m - 1
                gap = min(
                    gap, _segment_distance(points, first + index[v], decoded, before, here, d)
                )
            largest = max(largest, gap)
            for k in range(index[v] + 1, k_after):
                if after >= 0:
                    gap = _segment_distance(points, first + k, decoded, here, after, d)
                else:  # an open curve's points after its last vertex (none: it is kept)
                    gap = _segment_distance(points, first + k, decoded, here, here, d)
                largest = max(largest, gap)
            # the decoded vertex to the original polyline around it
            lo = index[v - 1] if v > 0 else (index[m - 1] - n if ring else 0)
            hi = index[v + 1] if v + 1 < m else (n + index[0] if ring else n - 1)
            if m == 1:
                lo, hi = 0, n if ring else n - 1
            gap = _to_original(decoded, here, points, first, n, ring, lo, hi, d)
            own = first + index[v]
            gap = min(gap, _segment_distance(decoded, here, points, own, own, d))
            largest = max(largest, gap)
        worst[c] = largest
        at += m
    return worst


@njit(cache=True, nogil=True)
def _offsets_by_cost(d, radius):
    """Every residual in ``[-radius, radius]**d``, cheapest to code first."""
    side = 2 * radius + 1
    count = side**d
    table = np.empty((count, d), dtype=np.int64)
    cost = np.empty(count, dtype=np.int64)
    for i in range(count):
        rest = i
        total = 0
        for j in range(d):
            r = rest % side - radius
            rest //= side
            table[i, j] = r
            total += 2 * _bit_length(abs(r)) + (r != 0)
        cost[i] = total * 64 + min(63, int(np.sum(np.abs(table[i]))))
    order = np.argsort(cost, kind="mergesort")
    return table[order], cost[order] // 64


@njit(cache=True, nogil=True)
def _residual_cost(r, d):
    total = 0
    for j in range(d):
        total += 2 * _bit_length(abs(r[j])) + (r[j] != 0)
    return total


@njit(cache=True, nogil=True)
def _frame_cost(zx, zy, x, y):
    """About the bits of the step ``(x, y)`` under the frame predictor of direction ``(zx, zy)``."""
    u, w = _to_frame(zx, zy, x, y)
    r = w - _across_prediction(zx, zy, u)
    return 2 * _bit_length(abs(u)) + (u != 0) + 2 * _bit_length(abs(r)) + (r != 0)


@njit(cache=True, nogil=True)
def refine_set(points, offsets, closed, keep, lattice, step, tolerance, order, radius):
    """Move each kept vertex to the lattice point nearest the coder's prediction that keeps the
    bound (in place on ``lattice``, the kept vertices in order).

    A vertex may slide along the curve: only the distance across it is bounded.  Vertex ``v``
    is tried at the prediction plus residuals in order of their coding cost (cheaper than its
    own residual only), and accepted where it lies within the tolerance of the original
    polyline around it, the original points before it are within the tolerance of the new
    segment from vertex ``v - 1``, those after it within the tolerance of the segment to vertex
    ``v + 1`` as it stands, and its own original point within the tolerance of the first.
    The next vertex then always still fits, so one pass suffices; the caller measures the
    bound on the decoded result all the same.
    """
    d = points.shape[1]
    table, costs = _offsets_by_cost(d, radius)
    frame = order >= 3 and d == 2
    tried = np.empty((len(table), d), dtype=np.int64)
    frame_cost = np.empty(len(table), dtype=np.int64)
    centre = 0  # the table's zero offset comes first (it is the cheapest)
    index = np.empty(points.shape[0] + 1, dtype=np.int64)
    seg = np.empty((2, d))
    cand = np.empty((1, d))
    predicted = np.empty(d, dtype=np.int64)
    residual = np.empty(d, dtype=np.int64)
    at = 0
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        m = 0
        for i in range(n):
            if keep[first + i]:
                index[m] = i
                m += 1
        ring = bool(closed[c]) and n > 2
        last = m if ring else m - 1
        for v in range(1, last):
            for j in range(d):
                step_before = lattice[at + v - 1, j] - lattice[at + v - 2, j] if v >= 2 else 0
                predicted[j] = lattice[at + v - 1, j] + ((min(order, 2) * step_before) >> 1)
                residual[j] = lattice[at + v, j] - predicted[j]
            own = _residual_cost(residual, d)
            after = at + v + 1 if v + 1 < m else at
            k_before, k_here = index[v - 1], index[v]
            k_after = index[v + 1] if v + 1 < m else n
            tries = 0
            if frame:
                zx, zy = _frame(lattice, at + v, at, order)
                if zx == 0 and zy == 0:
                    continue
                for t in range(len(table)):
                    x = lattice[at + v, 0] + table[t, 0] - lattice[at + v - 1, 0]
                    y = lattice[at + v, 1] + table[t, 1] - lattice[at + v - 1, 1]
                    frame_cost[t] = _frame_cost(zx, zy, x, y)
                ranked = np.argsort(frame_cost, kind="mergesort")
                own = frame_cost[centre]
                for t in ranked:
                    if frame_cost[t] >= own or tries == _REFINE_TRIES:
                        break
                    for j in range(d):
                        tried[tries, j] = lattice[at + v, j] + table[t, j]
                    tries += 1
            else:
                for t in range(len(table)):
                    if costs[t] >= own or tries == _REFINE_TRIES:
                        break
                    for j in range(d):
                        tried[tries, j] = predicted[j] + table[t, j]
                    tries += 1
            for t in range(tries):
                for j in range(d):
                    seg[0, j] = lattice[at + v - 1, j] * step
                    seg[1, j] = tried[t, j] * step
                    cand[0, j] = seg[1, j]
                # near the original polyline around it
                if _to_original(cand, 0, points, first, n, ring, k_before, k_after, d) > tolerance:
                    continue
                fits = _segment_distance(points, first + k_here, seg, 0, 1, d) <= tolerance
                k = k_before + 1
                while fits and k < k_here:
                    fits = _segment_distance(points, first + k, seg, 0, 1, d) <= tolerance
                    k += 1
                if not fits:
                    continue
                for j in range(d):
                    seg[0, j] = cand[0, j]
                    seg[1, j] = lattice[after, j] * step
                k = k_here + 1
                while fits and k < k_after:
                    fits = _segment_distance(points, first + (k % n), seg, 0, 1, d) <= tolerance
                    k += 1
                if fits:
                    for j in range(d):
                        lattice[at + v, j] = tried[t, j]
                    break
        at += m


@njit(cache=True, nogil=True)
def _reach(points, first, n, ring, i, way, length):
    """The index ``way`` (±1) of point ``i`` where the polyline has run ``length`` (or 32
    points, or an open curve's end)."""
    d = points.shape[1]
    k = i
    run = 0.0
    for _ in range(32):
        if not ring and (k + way < 0 or k + way > n - 1):
            break
        a, b = first + (k % n), first + ((k + way) % n)
        gap2 = 0.0
        for j in range(d):
            g = points[b, j] - points[a, j]
            gap2 += g * g
        run += np.sqrt(gap2)
        k += way
        if run >= length:
            break
    return k


@njit(cache=True, nogil=True)
def snap_set(points, offsets, closed, step, tolerance):
    """Lattice points for a lattice coarser than rounding allows.

    Each point takes, among the ``3**d`` lattice points around its rounded position, the one
    nearest to it of those within ``tolerance`` of its original polyline (within a lattice
    step and a half of it along the curve): a vertex may sit off its point along the curve,
    not across it.  Where none of them is (a sharp corner), the ``5**d`` around it (the
    polyline two and a half steps each way).  The ends of an open curve take their nearest
    lattice point.  Returns the lattice and 0 where a point found none (the ends: within
    ``tolerance`` of their point), 1 where every point found one among the ``3**d``, 2 where
    some needed the ``5**d``.
    """
    total, d = points.shape
    lattice = np.empty((total, d), dtype=np.int64)
    base = np.empty(d, dtype=np.int64)
    cand = np.empty((1, d))
    count = 3**d
    wide = 1
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        ring = bool(closed[c]) and n > 2
        for i in range(n):
            k = first + i
            for j in range(d):
                base[j] = np.int64(np.rint(points[k, j] / step))
                lattice[k, j] = base[j]
            end = not ring and (i == 0 or i == n - 1)
            if n == 1 or end:
                gap2 = 0.0
                for j in range(d):
                    g = base[j] * step - points[k, j]
                    gap2 += g * g
                if np.sqrt(gap2) > tolerance:
                    return lattice, 0
                continue
            own2 = 0.0
            for j in range(d):
                g = base[j] * step - points[k, j]
                own2 += g * g
            if own2 <= tolerance * tolerance:
                continue  # the nearest lattice point, and within the tolerance of the polyline
            best, best_own = np.inf, np.inf
            # the original polyline around the point: a lattice step and a half each way
            # (at most 32 segments, so the cost stays linear)
            lo = _reach(points, first, n, ring, i, -1, 1.5 * step)
            hi = _reach(points, first, n, ring, i, 1, 1.5 * step)
            for t in range(count):
                rest = t
                own2 = 0.0
                for j in range(d):
                    cand[0, j] = (base[j] + rest % 3 - 1) * step
                    rest //= 3
                    g = cand[0, j] - points[k, j]
                    own2 += g * g
                if not _near_original(cand, 0, points, first, n, ring, lo, hi, d, tolerance):
                    continue
                if own2 < best_own:
                    best, best_own = 0.0, own2
                    rest = t
                    for j in range(d):
                        lattice[k, j] = base[j] + rest % 3 - 1
                        rest //= 3
            if best > tolerance:  # none of the 3**d: the 5**d around (a sharp corner)
                wide = 2
                lo = _reach(points, first, n, ring, i, -1, 2.5 * step)
                hi = _reach(points, first, n, ring, i, 1, 2.5 * step)
                for t in range(5**d):
                    rest = t
                    own2 = 0.0
                    for j in range(d):
                        cand[0, j] = (base[j] + rest % 5 - 2) * step
                        rest //= 5
                        g = cand[0, j] - points[k, j]
                        own2 += g * g
                    if own2 >= best_own:
                        continue
                    if not _near_original(cand, 0, points, first, n, ring, lo, hi, d, tolerance):
                        continue
                    best, best_own = 0.0, own2
                    rest = t
                    for j in range(d):
                        lattice[k, j] = base[j] + rest % 5 - 2
                        rest //= 5
            if best > tolerance:
                return lattice, 0
    return lattice, wide


@njit(cache=True, nogil=True)
def _span_to(points, first, n, a, b, seg, tolerance, d):
    """Whether every point ``a + 1 … b`` (ring indices) lies within ``tolerance`` of the
    segment ``seg[0]``–``seg[1]``."""
    for k in range(a + 1, b + 1):
        if _segment_distance(points, first + (k % n), seg, 0, 1, d) > tolerance:
            return False
    return True


@njit(cache=True, nogil=True)
def _end_candidates(points, lattice, first, n, ring, b, step, tolerance, out):
    """The lattice points around point ``b``'s own within ``tolerance`` of the original
    polyline near it (a lattice step and a half along it either way); their count."""
    d = points.shape[1]
    k = first + (b % n)
    cand = np.empty((1, d))
    count = 0
    lo = _reach(points, first, n, ring, b % n, -1, 1.5 * step)
    hi = _reach(points, first, n, ring, b % n, 1, 1.5 * step)
    for t in range(3**d):
        rest = t
        for j in range(d):
            out[count, j] = lattice[k, j] + rest % 3 - 1
            rest //= 3
            cand[0, j] = out[count, j] * step
        if _near_original(cand, 0, points, first, n, ring, lo, hi, d, tolerance):
            count += 1
    return count


@njit(cache=True, nogil=True)
def lifted_reach_set(points, lattice, offsets, closed, step, tolerance, window):
    """Greedy farthest reach whose vertices may sit off the curve (in place on ``lattice``).

    As :func:`reach_set`, but a segment's end may be any lattice point around its point that
    lies within ``tolerance`` of the original polyline, not only the point's own: on an arc a
    vertex lifted to the outside lets the chord dip inside, so a segment may bend away from
    the curve by the tolerance on both sides, not one.  Of the ends that keep the farthest
    span, the one from which the next span reaches farthest is taken.  The ends of an open
    curve and the start of a closed one keep their own lattice points.  Returns the mask of
    kept points; their chosen lattice points are written into ``lattice``.
    """
    total, d = points.shape
    keep = np.zeros(total, dtype=np.bool_)
    count = 3**d
    cands = np.empty((count, d), dtype=np.int64)
    seg = np.empty((2, d))
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        if n == 0:
            continue
        is_ring = bool(closed[c]) and n > 2
        last = n if is_ring else n - 1
        keep[first] = True
        keep[first + (last % n)] = True
        a = 0
        while a < last:
            top = min(last, a + window)
            for j in range(d):
                seg[0, j] = lattice[first + (a % n), j] * step

            best = a + 1
            span = 1
            fail = top + 1
            while a + span <= top:
                if (
                    _fits_any(
                        points,
                        lattice,
                        first,
                        n,
                        is_ring,
                        a,
                        a + span,
                        last,
                        step,
                        tolerance,
                        seg,
                        cands,
                    )
                    >= 0
                ):
                    best = a + span
                    span *= 2
                else:
                    fail = a + span
                    break
            if fail > top and best < top:
                if (
                    _fits_any(
                        points,
                        lattice,
                        first,
                        n,
                        is_ring,
                        a,
                        top,
                        last,
                        step,
                        tolerance,
                        seg,
                        cands,
                    )
                    >= 0
                ):
                    best = top
                else:
                    fail = top
            while fail - best > 1:
                middle = (best + fail) // 2
                if (
                    _fits_any(
                        points,
                        lattice,
                        first,
                        n,
                        is_ring,
                        a,
                        middle,
                        last,
                        step,
                        tolerance,
                        seg,
                        cands,
                    )
                    >= 0
                ):
                    best = middle
                else:
                    fail = middle
            b = best + 2
            while b <= min(top, best + 4):
                if (
                    _fits_any(
                        points, lattice, first, n, is_ring, a, b, last, step, tolerance, seg, cands
                    )
                    >= 0
                ):
                    best = b
                b += 1
            # the end: of the positions that keep the span, the one the next span reaches
            # farthest from (its own lattice point first on ties)
            if best < last:
                found = _end_candidates(
                    points, lattice, first, n, is_ring, best, step, tolerance, cands
                )
                own = first + (best % n)
                chosen = -1
                chosen_reach = -1
                for t in range(found):
                    for j in range(d):
                        seg[1, j] = cands[t, j] * step
                    if not _span_to(points, first, n, a, best, seg, tolerance, d):
                        continue
                    reach = _next_reach(
                        points, lattice, first, n, best, last, cands[t], step, tolerance, window
                    )
                    same = True
                    for j in range(d):
                        same = same and cands[t, j] == lattice[own, j]
                    if reach > chosen_reach or (reach == chosen_reach and same):
                        chosen, chosen_reach = t, reach
                if chosen >= 0:
                    for j in range(d):
                        lattice[own, j] = cands[chosen, j]
            keep[first + (best % n)] = True
            a = best
    return keep


@njit(cache=True, nogil=True)
def _fits_any(points, lattice, first, n, ring, a, b, last, step, tolerance, seg, cands):
    """The index of an end position for point ``b`` that keeps the span from ``a`` (whose
    position is ``seg[0]``), or -1.  The last point of the curve keeps its own position."""
    d = points.shape[1]
    if b >= last:
        for j in range(d):
            seg[1, j] = lattice[first + (b % n), j] * step
        return 0 if _span_to(points, first, n, a, b, seg, tolerance, d) else -1
    own = first + (b % n)
    for j in range(d):
        seg[1, j] = lattice[own, j] * step
    if _span_to(points, first, n, a, b, seg, tolerance, d):
        return 0
    found = _end_candidates(points, lattice, first, n, ring, b, step, tolerance, cands)
    for t in range(found):
        for j in range(d):
            seg[1, j] = cands[t, j] * step
        if _span_to(points, first, n, a, b, seg, tolerance, d):
            return t
    return -1


@njit(cache=True, nogil=True)
def _next_reach(points, lattice, first, n, a, last, position, step, tolerance, window):
    """How far a span from point ``a`` at lattice ``position`` reaches, to the points' own
    lattice positions (galloping, as :func:`reach_set`)."""
    d = points.shape[1]
    seg = np.empty((2, d))
    for j in range(d):
        seg[0, j] = position[j] * step
    top = min(last, a + window)
    best = a + 1
    span = 1
    while a + span <= top:
        b = a + span
        for j in range(d):
            seg[1, j] = lattice[first + (b % n), j] * step
        if not _span_to(points, first, n, a, b, seg, tolerance, d):
            break
        best = b
        span *= 2
    return best


# --- version 3: bulged segments -----------------------------------------------------------------


@njit(cache=True, nogil=True)
def _bulge_points(ax, ay, bx, by, middle, out, at):
    """The ``BULGE_PARTS - 1`` inner points of the parabola from ``(ax, ay)`` to ``(bx, by)``
    whose middle lies ``middle`` to the left of the chord, written into ``out[at:]``.

    Plain float64 arithmetic on the decoded vertices (``sqrt`` is correctly rounded), so the
    encoder's check and every decoder compute the same points.  None for a zero-length chord.
    """
    dx, dy = bx - ax, by - ay
    length = np.sqrt(dx * dx + dy * dy)
    if length == 0.0 or middle == 0.0:
        return 0
    nx, ny = -dy / length, dx / length
    for i in range(1, BULGE_PARTS):
        s = i / BULGE_PARTS
        off = 4.0 * s * (1.0 - s) * middle
        out[at + i - 1, 0] = ax + s * dx + off * nx
        out[at + i - 1, 1] = ay + s * dy + off * ny
    return BULGE_PARTS - 1


@njit(cache=True, nogil=True)
def bulged_polylines(vertices, counts, closed, bulges, unit):
    """The decoded polylines of version 3: each curve's vertices (float64, ``(total, 2)``) with
    every bulged segment's inner points between its ends.  Returns the points, each curve's
    point count, and each vertex's row among the points."""
    extra = 0
    for i in range(len(bulges)):
        if bulges[i] != 0:
            extra += BULGE_PARTS - 1
    out = np.empty((len(vertices) + extra, 2))
    sizes = np.zeros(len(counts), dtype=np.int64)
    rows = np.empty(len(vertices), dtype=np.int64)
    at = 0
    w = 0
    for c in range(len(counts)):
        m = counts[c]
        start = w
        for v in range(at, at + m):
            if v > at:
                w += _bulge_points(
                    vertices[v - 1, 0],
                    vertices[v - 1, 1],
                    vertices[v, 0],
                    vertices[v, 1],
                    bulges[v] * unit,
                    out,
                    w,
                )
            rows[v] = w
            out[w, 0] = vertices[v, 0]
            out[w, 1] = vertices[v, 1]
            w += 1
        if closed[c] and m > 1:
            w += _bulge_points(
                vertices[at + m - 1, 0],
                vertices[at + m - 1, 1],
                vertices[at, 0],
                vertices[at, 1],
                bulges[at] * unit,
                out,
                w,
            )
        sizes[c] = w - start
        at += m
    return out[:w], sizes, rows


@njit(cache=True, nogil=True)
def _to_chain(points, k, chain, lo, hi):
    """Distance from ``points[k]`` to the polyline ``chain[lo] … chain[hi]``."""
    best = np.inf
    if hi == lo:
        return _segment_distance(points, k, chain, lo, lo, 2)
    for i in range(lo, hi):
        best = min(best, _segment_distance(points, k, chain, i, i + 1, 2))
    return best


@njit(cache=True, nogil=True)
def _bulged_fit(points, decoded, first, n, a, b, tolerance, unit, chain, strict):
    """The bulge (in ``unit``) whose parabola from decoded point ``a`` to ``b`` (ring indices)
    keeps the points between within ``tolerance`` and its inner points within ``tolerance``
    of the original segments ``a … b - 1``; 0 for the straight segment; ``_NO_FIT`` if none.
    Tried: straight, then the bulge through the point farthest from the chord and its two
    neighbours, the smaller first.  ``strict`` 1: the span's ends too must lie within
    ``tolerance`` of it (the check measures them against both their spans; some sets need it
    to pass); 2: straight spans only (:func:`reach_set`'s test)."""
    ia, ib = first + (a % n), first + (b % n)
    ax, ay = decoded[ia, 0], decoded[ia, 1]
    bx, by = decoded[ib, 0], decoded[ib, 1]
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    guess = 0.0
    widest = 0.0
    if length2 > 0.0:
        for k in range(a + 1, b):
            p = first + (k % n)
            px, py = points[p, 0] - ax, points[p, 1] - ay
            s = (px * dx + py * dy) / length2
            if 0.0 < s < 1.0 and s * (1.0 - s) > widest:
                widest = s * (1.0 - s)
                guess = (-px * dy + py * dx) / np.sqrt(length2) / (4.0 * widest)
    centre = np.int64(np.rint(guess / unit)) if unit > 0 and abs(guess / unit) < 1e9 else 0
    chain[0, 0], chain[0, 1] = ax, ay
    # the smallest bulge first (the cheapest to code): 0, then the guess's side nearer zero
    toward = -1 if centre > 0 else 1
    for t in range(4):
        bulge = 0 if t == 0 else centre + (0, toward, 0, -toward)[t]
        if t > 0 and (bulge == 0 or strict >= 2):
            continue
        if t == 1 and (centre + toward == 0 or centre == 0):
            continue
        inner = _bulge_points(ax, ay, bx, by, bulge * unit, chain, 1)
        chain[inner + 1, 0], chain[inner + 1, 1] = bx, by
        fits = True
        ends = 1 if strict == 1 else 0
        for k in range(a + 1 - ends, b + ends):
            if _to_chain(points, first + (k % n), chain, 0, inner + 1) > tolerance:
                fits = False
                break
        for i in range(1, inner + 1):
            if not fits:
                break
            best = np.inf
            for s in range(a, b):
                best = min(
                    best,
                    _segment_distance(chain, i, points, first + (s % n), first + ((s + 1) % n), 2),
                )
            fits = best <= tolerance
        if fits:
            return bulge
    return _NO_FIT


_NO_FIT = 1 << 62


@njit(cache=True, nogil=True)
def bulged_reach_set(points, decoded, offsets, closed, tolerance, window, unit, bulges, strict):
    """Greedy farthest reach (:func:`reach_set`, from each curve's point 0) where a span may be
    a parabola (:func:`_bulged_fit`): on an arc it follows the curve, so it reaches several
    times as far as a chord.  Writes each span's bulge at the row of its end (a closed curve's
    closing span at its first row) into ``bulges``; returns the mask of the kept points.
    ``strict`` per curve: see :func:`_bulged_fit`."""
    total = points.shape[0]
    keep = np.zeros(total, dtype=np.bool_)
    chain = np.empty((BULGE_PARTS + 1, 2))
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        if n == 0:
            continue
        ring = n + 1 if closed[c] and n > 2 else n
        last = ring - 1
        keep[first] = True
        keep[first + (last % n)] = True
        a = 0
        while a < last:
            top = min(last, a + window)
            best = a + 1
            best_bulge = 0
            span = 2
            fail = top + 1
            while a + span <= top:
                found = _bulged_fit(
                    points, decoded, first, n, a, a + span, tolerance, unit, chain, strict[c]
                )
                if found != _NO_FIT:
                    best, best_bulge = a + span, found
                    span *= 2
                else:
                    fail = a + span
                    break
            if fail > top and best < top:
                found = _bulged_fit(
                    points, decoded, first, n, a, top, tolerance, unit, chain, strict[c]
                )
                if found != _NO_FIT:
                    best, best_bulge = top, found
                else:
                    fail = top
            while fail - best > 1:
                middle = (best + fail) // 2
                found = _bulged_fit(
                    points, decoded, first, n, a, middle, tolerance, unit, chain, strict[c]
                )
                if found != _NO_FIT:
                    best, best_bulge = middle, found
                else:
                    fail = middle
            keep[first + (best % n)] = True
            bulges[first + (best % n)] = best_bulge
            a = best
    return keep


@njit(cache=True, nogil=True)
def check_bulged(points, offsets, closed, keep, out, sizes, rows):
    """The largest deviation, both ways, of each curve of version 3 (an upper bound).

    ``out`` holds the decoded polylines (:func:`bulged_polylines`), ``rows`` each vertex's row
    in it.  Per span between kept points ``a`` and ``b``: each original point strictly between
    to the decoded points from vertex ``a`` to ``b``, each decoded inner point to the original
    segments ``a … b - 1``; each kept point to the decoded points of its two spans, each vertex
    to the original segments of its two spans.  Each is a minimum over part of a polyline.
    """
    worst = np.zeros(len(offsets) - 1)
    index = np.empty(points.shape[0] + 1, dtype=np.int64)
    at = 0
    w = 0
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        m = 0
        for i in range(n):
            if keep[first + i]:
                index[m] = i
                m += 1
        ring = bool(closed[c]) and n > 2
        end = w + sizes[c]  # one past the curve's last decoded point
        largest = 0.0
        spans = m if ring else m - 1
        if m == 1:
            largest = _to_chain(points, first, out, w, w)
            for k in range(first, stop):
                largest = max(largest, _to_chain(points, k, out, w, end - 1))
        for v in range(max(spans, 0)):
            ka = index[v]
            kb = index[v + 1] if v + 1 < m else n + index[0]
            lo = rows[at + v]
            hi = rows[at + v + 1] if v + 1 < m else end  # ``end`` stands for the first again
            # the chain lo … hi (hi == end: the first vertex again)
            for k in range(ka + 1, kb):  # kept points: below, against both spans
                p = first + (k % n)
                if hi == end:
                    gap = _to_chain(points, p, out, lo, end - 1)
                    gap = min(gap, _segment_distance(points, p, out, end - 1, w, 2))
                else:
                    gap = _to_chain(points, p, out, lo, hi)
                largest = max(largest, gap)
            for i in range(lo + 1, hi):
                best = np.inf
                for s in range(ka, kb):
                    best = min(
                        best,
                        _segment_distance(
                            out, i, points, first + (s % n), first + ((s + 1) % n), 2
                        ),
                    )
                largest = max(largest, best)
        # kept points against the decoded points of both their spans, vertices against the
        # original segments of both
        for v in range(m):
            p = first + index[v]
            here = rows[at + v]
            nxt = rows[at + v + 1] if v + 1 < m else (end if ring else here)
            prv = rows[at + v - 1] if v > 0 else (rows[at + m - 1] if ring else here)
            gap = _to_chain(points, p, out, here, min(nxt, end - 1))
            if ring and v + 1 == m:
                gap = min(gap, _segment_distance(points, p, out, end - 1, w, 2))
            if v > 0:
                gap = min(gap, _to_chain(points, p, out, prv, here))
            elif ring:
                gap = min(gap, _to_chain(points, p, out, prv, end - 1))
                gap = min(gap, _segment_distance(points, p, out, end - 1, w, 2))
            largest = max(largest, gap)
            lo = index[v - 1] if v > 0 else (index[m - 1] - n if ring else 0)
            hi = index[v + 1] if v + 1 < m else (n + index[0] if ring else n - 1)
            if m == 1:
                lo, hi = 0, n if ring else n - 1
            gap = _to_original(out, here, points, first, n, ring, lo, hi, 2)
            gap = min(gap, _segment_distance(out, here, points, p, p, 2))
            largest = max(largest, gap)
        worst[c] = largest
        at += m
        w = end
    return worst


@njit(cache=True, nogil=True)
def nearest_corner_starts(lattice, offsets, corner):
    """Each curve's start (a row offset within it): the first of its ``corner`` rows whose
    lattice point is the fewest coded bits (per coordinate ``2 × bit length + sign``) from
    the previous curve's first point after its own start; 0 where it has no corner."""
    count = len(offsets) - 1
    d = lattice.shape[1]
    starts = np.zeros(count, dtype=np.int64)
    previous = np.zeros(d, dtype=np.int64)
    for c in range(count):
        first, stop = offsets[c], offsets[c + 1]
        if stop == first:
            continue
        best = -1
        best_bits = 0
        for r in range(first, stop):
            if not corner[r]:
                continue
            bits = 0
            for k in range(d):
                gap = abs(lattice[r, k] - previous[k])
                length = 0
                while gap >> length:
                    length += 1
                bits += 2 * length + (1 if gap != 0 else 0)
            if best < 0 or bits < best_bits:
                best, best_bits = r, bits
        if best >= 0:
            starts[c] = best - first
        for k in range(d):
            previous[k] = lattice[first + starts[c], k]
    return starts


@njit(cache=True, nogil=True)
def optimal_bulged_set(
    points, decoded, offsets, closed, tolerance, window, unit, strict, greedy, bulges
):
    """The fewest parabolic spans on each curve (as :func:`optimal_set`, with
    :func:`_bulged_fit`'s test), from each curve's point 0.  ``greedy`` and ``bulges`` hold
    :func:`bulged_reach_set`'s result, kept for a curve whose tests would exceed the work
    budget; elsewhere ``bulges`` is rewritten.  Returns the mask of the kept points."""
    total = points.shape[0]
    keep = np.zeros(total, dtype=np.bool_)
    chain = np.empty((BULGE_PARTS + 1, 2))
    for c in range(len(offsets) - 1):
        first, stop = offsets[c], offsets[c + 1]
        n = stop - first
        if n == 0:
            continue
        ring = n + 1 if closed[c] and n > 2 else n
        last = ring - 1
        dist = np.full(last + 1, 1 << 40, dtype=np.int64)
        previous = np.full(last + 1, -1, dtype=np.int64)
        chosen = np.zeros(last + 1, dtype=np.int64)
        dist[0] = 0
        budget = 256 * n + (1 << 16)
        for a in range(last):
            if budget < 0:
                break
            top = min(last, a + window)
            for b in range(a + 1, top + 1):
                if dist[a] + 1 >= dist[b]:
                    continue
                budget -= 4 * (b - a)
                found = _bulged_fit(
                    points, decoded, first, n, a, b, tolerance, unit, chain, strict[c]
                )
                if found != _NO_FIT:
                    dist[b] = dist[a] + 1
                    previous[b] = a
                    chosen[b] = found
        if budget < 0 or dist[last] >= 1 << 40:
            for i in range(first, stop):
                keep[i] = greedy[i]
            continue
        for i in range(first, stop):
            if not greedy[i]:
                bulges[i] = 0
        at = last
        while at > 0:
            keep[first + (at % n)] = True
            bulges[first + (at % n)] = chosen[at]
            at = previous[at]
        keep[first] = True
        if ring == n:
            bulges[first] = 0
    return keep


_HALVES = _parse_priors("")
_PRIORS = _parse_priors(_PRIOR_TABLE + " " + _COPY_PRIOR_TABLE)
