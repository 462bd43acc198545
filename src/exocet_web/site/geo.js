// Exocet web map: geodesy for the page (no library): WGS 84 latitude/longitude to UTM with the transverse Mercator
// projection in Krueger's series to the sixth order in n (Karney 2011, "Transverse Mercator with an accuracy of a
// few nanometers"), so within a zone the page's UTM read-out agrees with GeographicLib to far better than a
// millimetre (test/test_geo_js.cpp checks it). Also the scale factor and the meridian convergence, and a distance
// on the ellipsoid for short lines (the UTM distance divided by the mean scale factor).
(function (root) {
  'use strict';

  const A = 6378137.0;               // WGS 84 semi-major axis (m)
  const F = 1 / 298.257223563;       // flattening
  const K0 = 0.9996;                 // UTM central scale factor
  const N = F / (2 - F);             // third flattening
  const E = 2 * Math.sqrt(N) / (1 + N);  // eccentricity
  const N2 = N * N, N3 = N2 * N, N4 = N3 * N, N5 = N4 * N, N6 = N5 * N;
  // Rectifying radius.
  const A_RECT = A / (1 + N) * (1 + N2 / 4 + N4 / 64 + N6 / 256);
  // Krueger's alpha coefficients (conformal -> rectifying), to n^6.
  const ALPHA = [
    N / 2 - 2 * N2 / 3 + 5 * N3 / 16 + 41 * N4 / 180 - 127 * N5 / 288 + 7891 * N6 / 37800,
    13 * N2 / 48 - 3 * N3 / 5 + 557 * N4 / 1440 + 281 * N5 / 630 - 1983433 * N6 / 1935360,
    61 * N3 / 240 - 103 * N4 / 140 + 15061 * N5 / 26880 + 167603 * N6 / 181440,
    49561 * N4 / 161280 - 179 * N5 / 168 + 6601661 * N6 / 7257600,
    34729 * N5 / 80640 - 3418889 * N6 / 1995840,
    212378941 * N6 / 319334400,
  ];
  const DEG = Math.PI / 180;

  function atanh(x) { return 0.5 * Math.log((1 + x) / (1 - x)); }

  /** The standard UTM zone (1..60) of a longitude (degrees); the Norway and Svalbard exceptions are not applied. */
  function utmZone(lonDeg) {
    let lon = ((lonDeg + 180) % 360 + 360) % 360 - 180;
    return Math.min(60, Math.floor((lon + 180) / 6) + 1);
  }

  /**
   * Transverse Mercator of (latDeg, lonDeg) about the central meridian lon0Deg, scale K0, no false origin.
   * Returns {x, y} metres with the scale factor k and the convergence gammaDeg (grid north clockwise from true).
   */
  function transverseMercator(latDeg, lonDeg, lon0Deg) {
    const phi = latDeg * DEG;
    let dLon = ((lonDeg - lon0Deg + 540) % 360 + 360) % 360 - 180;
    const lambda = dLon * DEG;
    const sinPhi = Math.sin(phi);
    // Conformal latitude: tan(chi) = t.
    const t = Math.sinh(atanh(sinPhi) - E * atanh(E * sinPhi));
    const cosL = Math.cos(lambda), sinL = Math.sin(lambda);
    const xi1 = Math.atan2(t, cosL);
    const eta1 = atanh(sinL / Math.sqrt(1 + t * t));
    let xi = xi1, eta = eta1, sigma = 1, tau = 0;
    for (let j = 1; j <= 6; ++j) {
      const a = ALPHA[j - 1];
      xi += a * Math.sin(2 * j * xi1) * Math.cosh(2 * j * eta1);
      eta += a * Math.cos(2 * j * xi1) * Math.sinh(2 * j * eta1);
      sigma += 2 * j * a * Math.cos(2 * j * xi1) * Math.cosh(2 * j * eta1);
      tau += 2 * j * a * Math.sin(2 * j * xi1) * Math.sinh(2 * j * eta1);
    }
    const tanPhi = Math.tan(phi);
    const k = K0 * A_RECT / A * Math.sqrt((1 + Math.pow((1 - N) / (1 + N) * tanPhi, 2)) *
                                          (sigma * sigma + tau * tau) / (t * t + cosL * cosL));
    const gamma = Math.atan2(tau, sigma) + Math.atan2(t * Math.tan(lambda), Math.sqrt(1 + t * t));
    return { x: K0 * A_RECT * eta, y: K0 * A_RECT * xi, k: k, gammaDeg: gamma / DEG };
  }

  /**
   * UTM coordinates of a WGS 84 point, in `zone` (1..60; default: the point's own) and hemisphere (`northern`,
   * default: the point's). Points outside the zone are projected in it (extended, as the dive's tiles are).
   * Returns {easting, northing, zone, northern, k, gammaDeg}.
   */
  function toUtm(latDeg, lonDeg, zone, northern) {
    const z = zone || utmZone(lonDeg);
    const north = northern === undefined ? latDeg >= 0 : northern;
    const p = transverseMercator(latDeg, lonDeg, 6 * z - 183);
    return { easting: 500000 + p.x, northing: (north ? 0 : 10000000) + p.y, zone: z, northern: north, k: p.k,
             gammaDeg: p.gammaDeg };
  }

  /** Distance (m) on the ellipsoid between two points a few km apart at most: UTM distance / mean scale factor. */
  function distance(lat1, lon1, lat2, lon2) {
    const zone = utmZone((lon1 + lon2) / 2);
    const a = toUtm(lat1, lon1, zone, true), b = toUtm(lat2, lon2, zone, true);
    const m = toUtm((lat1 + lat2) / 2, (lon1 + lon2) / 2, zone, true);
    const k = (a.k + 4 * m.k + b.k) / 6;  // Simpson's rule along the line
    return Math.hypot(b.easting - a.easting, b.northing - a.northing) / k;
  }

  /** Latitude or longitude as degrees and decimal minutes, e.g. 43 deg 04.27191' N. */
  function degreesMinutes(value, positive, negative) {
    const hemisphere = value >= 0 ? positive : negative;
    const v = Math.abs(value);
    let d = Math.floor(v), m = (v - d) * 60;
    if (m >= 59.999995) { d += 1; m = 0; }
    return d + '\u00b0' + (m < 10 ? '0' : '') + m.toFixed(5) + '\u2032' + hemisphere;
  }

  root.ExocetGeo = { utmZone, transverseMercator, toUtm, distance, degreesMinutes };
})(typeof window !== 'undefined' ? window : this);
